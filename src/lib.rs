//! relume: one bounce of indirect light, diffuse and glossy, from thousands of virtual area
//! lights (VALs), computed on the GPU with the sparse model-space shading method of Lensing &
//! Broll 2013 (see `DESIGN.md` in the shared specification).
//!
//! # Conventions
//!
//! - Units: metres; flux in W, radiant intensity in W/sr, irradiance in W/m², radiance in
//!   W/(m² sr); colours are linear RGB until an image is written (`image`).
//! - Coordinates: right-handed world space, +Y up by convention of the fixtures; cameras look
//!   down their local -Z; every pose is camera-to-world. Clip space is wgpu's (z in [0, 1]).
//! - Angles in scene files are degrees; inside relume they are radians.
//!
//! # Layout
//!
//! - [`scene`]: scene files (JSON), OBJ/MTL loading, subdivision, sparse points and neighbours.
//! - [`reference`]: the CPU twin of every GPU computation: the readable statement of the maths.
//! - [`gpu`]: the device and one module per pass, each with its WGSL file in `shaders/`.
//! - [`renderer`]: a frame, the passes called in order.
//! - [`rgbd`]: RGB-D recordings and frames as light sources; [`mr`]: relighting them (mixed reality).
//! - [`image`]: tone mapping, PNG/EXR output, error metrics; [`compare`]: the error and timing
//!   figures of `relume compare`, which [`bench`] (`relume bench`, sweeps and plots) shares.
//! - [`rgbd`]: RGB-D frames and how they become VALs.
//! - [`service`]: `relume serve`, the HTTP + WebSocket service, a client of it
//!   (`service::client`) and its load benchmark (`service::load`).
//!
//! # Who owns the GPU
//!
//! One [`gpu::Gpu`] owns the wgpu device and queue and lives on one thread; passes and the
//! renderer borrow it. Everything is headless. In the service that thread is
//! `service::gpu_worker`'s: handlers send it jobs over a bounded channel.

pub mod bench;
pub mod compare;
pub mod gpu;
pub mod image;
pub mod mr;
pub mod reference;
pub mod renderer;
pub mod replay;
pub mod rgbd;
pub mod scene;
pub mod service;
