//! relume: one bounce of indirect light, diffuse and glossy, from thousands of virtual area
//! lights (VALs), computed on the GPU with the sparse model-space shading method of Lensing &
//! Broll 2013 (see `docs/design.md`).
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
//! - [`gpu`]: the device and the techniques, one folder each with its WGSL beside its Rust:
//!   `lights/` (spot light RSM VALs and direct light, RGB-D VALs), `raster/` (visibility
//!   buffers), `sparse/` (gather, renormalise, interpolate, shade), `visibility/` (the sparse
//!   method's visibility modes), `references/` (brute force, exact visibility).
//! - [`renderer`]: a frame, the ordered list of the techniques it needs.
//! - [`twin`]: the CPU twin of every GPU computation: the readable statement of the maths
//!   (a visibility mode keeps its twin in its own folder, e.g. `gpu::visibility::disks::twin`).
//! - [`rgbd`]: RGB-D recordings and frames as light sources; [`mr`]: relighting them (mixed
//!   reality), `mr::replay` replaying a recording.
//! - [`image`]: tone mapping, PNG/EXR output, error metrics; [`val`]: the virtual area light, the
//!   plain data type every layer exchanges.
//! - [`bench`]: `relume bench` (sweeps and plots) and `bench::compare`, the figures of
//!   `relume compare`, one code path.
//! - [`service`]: `relume serve`, the HTTP + WebSocket service, a client of it
//!   (`service::client`) and its load benchmark and soak test (`service::load`).
//!
//! # Who owns the GPU
//!
//! One [`gpu::Gpu`] owns the wgpu device and queue and lives on one thread; passes and the
//! renderer borrow it. Everything is headless. In the service that thread is
//! `service::gpu_worker`'s: handlers send it jobs over a bounded channel.

pub mod bench;
pub mod gpu;
pub mod image;
pub mod mr;
pub mod renderer;
pub mod rgbd;
pub mod scene;
pub mod service;
pub mod twin;
pub mod val;
