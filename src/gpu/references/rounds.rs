//! What the per-pixel passes that cast shadow rays through the scene's BVH share (the exact
//! pass and its estimator): the BVH's buffers, the per-pixel `progress` of a pass run in rounds
//! under llvmpipe's loop limit (`shader/rounds.wgsl`), and the host's loop that dispatches
//! rounds until no pixel is left.

use crate::gpu::pass::{Kernel, PassDesc, Res, buffer, module_from_source, view};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::TILE_SIZE;
use crate::gpu::technique::Frame;
use crate::gpu::timing::{Span, StageTimings};
use crate::gpu::{Gpu, GpuError};
use crate::twin::bvh::Bvh;
use std::time::Instant;

/// The segment queries through the BVH (`bvh.wgsl`: bindings 4 and 5 of the pass including it).
pub const BVH_WGSL: &str = include_str!("bvh.wgsl");

/// The BVH of `scene`'s meshes as placed now (obvhs, flattened for `bvh.wgsl`): its nodes and its
/// triangle order, the buffers `<label>.bvh_nodes` and `<label>.bvh_triangles`.
pub fn bvh_buffers(gpu: &Gpu, scene: &GpuScene, label: &str) -> Result<(wgpu::Buffer, wgpu::Buffer), GpuError> {
    let flat = &scene.flat;
    let positions: Vec<glam::Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let bvh = Bvh::build(&positions, &triangles);
    let none = wgpu::BufferUsages::empty();
    let nodes = gpu.storage_buffer(&format!("{label}.bvh_nodes"), &bvh.nodes, none)?;
    let order = gpu.storage_buffer(&format!("{label}.bvh_triangles"), &bvh.order, none)?;
    Ok((nodes, order))
}

/// A pass over the image's pixels in rounds, with the scene's BVH bound.
pub struct PixelRounds {
    pass: &'static PassDesc,
    kernel: Kernel,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    /// Per pixel: where its next round resumes (`progress` in `rounds.wgsl`), sized to the
    /// largest image rendered so far.
    progress: wgpu::Buffer,
    pixels: usize,
    /// [pixels left after a round, pixels that made no progress in it].
    status: wgpu::Buffer,
}

impl PixelRounds {
    /// Build the BVH of `scene` (obvhs, flattened for `bvh.wgsl`) and `pass` from its WGSL
    /// `body`, for the lobes `glossy` says, in `workgroup`s.
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        pass: &'static PassDesc,
        body: &str,
        glossy: bool,
        workgroup: [u32; 3],
    ) -> Result<Self, GpuError> {
        let label = pass.label;
        let (nodes, order) = bvh_buffers(gpu, scene, label)?;
        let source = pass.source_with(body, scene.textured(), workgroup, TILE_SIZE);
        let module = module_from_source(gpu, label, source)?;
        let kernel = Kernel::build(gpu, scene, pass, &module, pass.lobe_entry(glossy), &[], workgroup)?;
        let progress = gpu.storage_buffer_sized::<u32>(&format!("{label}.progress"), 0)?;
        let status = gpu.storage_buffer_sized::<u32>(&format!("{label}.status"), 2)?;
        Ok(Self { pass, kernel, nodes, order, progress, pixels: 0, status })
    }

    /// Make room for an image of `pixels` pixels; whether the buffers grew.
    pub fn fit(&mut self, gpu: &Gpu, pixels: usize) -> Result<bool, GpuError> {
        if pixels <= self.pixels {
            return Ok(false);
        }
        self.progress = gpu.storage_buffer_sized::<u32>(&format!("{}.progress", self.pass.label), pixels)?;
        self.pixels = pixels;
        Ok(true)
    }

    /// The bind group: the pass's bindings 0-7 (visibility, indirect, VALs, their count, the
    /// BVH, progress, status) and `more`.
    pub fn bind<'a>(&'a self, gpu: &Gpu, frame: &Frame<'a>, more: Vec<Res<'a>>) -> wgpu::BindGroup {
        let mut resources = vec![
            view("visibility", &frame.camera.view.view),
            buffer("indirect", &frame.camera.indirect),
            buffer("vals", &frame.vals.buffer),
            buffer("val_count", &frame.vals.count),
            buffer("bvh_nodes", &self.nodes),
            buffer("bvh_triangles", &self.order),
            buffer("progress", &self.progress),
            buffer("status", &self.status),
        ];
        resources.extend(more);
        self.kernel.bind(gpu, &resources)
    }

    /// The first round: every pixel's progress zeroed, then one dispatch.
    pub fn first_round(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        frame: &Frame<'_>,
        group: &wgpu::BindGroup,
        span: Option<Span<'_>>,
    ) {
        let camera = &frame.camera.view;
        encoder.clear_buffer(&self.progress, 0, Some(u64::from(camera.width * camera.height) * 4));
        self.dispatch(encoder, frame, group, span);
    }

    /// One round over the image.
    fn dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        frame: &Frame<'_>,
        group: &wgpu::BindGroup,
        span: Option<Span<'_>>,
    ) {
        encoder.clear_buffer(&self.status, 0, None);
        let camera = &frame.camera.view;
        let invocations = [camera.width, camera.height, 1];
        self.kernel.dispatch(encoder, group, frame.scene, invocations, span.as_ref().map(Span::compute));
    }

    /// After the first round was submitted: further rounds, each submitted and waited for,
    /// until no pixel is left (`what` and `budget`, the loop budget per round, name the pixels
    /// in the error when some make no progress); their wall time is added to the pass's stage.
    /// Returns the rounds it took in all.
    pub fn finish(
        &self,
        gpu: &Gpu,
        frame: &Frame<'_>,
        group: &wgpu::BindGroup,
        timings: &mut StageTimings,
        what: &str,
        budget: u32,
    ) -> Result<u32, GpuError> {
        let start = Instant::now();
        let mut count = 1;
        loop {
            if crate::gpu::rounds_done(gpu, &self.status, count, what, budget)? {
                break;
            }
            let label = format!("{}.round", self.pass.label);
            let mut encoder =
                gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(&label) });
            self.dispatch(&mut encoder, frame, group, None);
            gpu.submit_and_wait(encoder)?;
            count += 1;
        }
        if count > 1 {
            timings.add(self.pass.label, start.elapsed().as_secs_f64() * 1e3);
        }
        Ok(count)
    }
}
