//! A compute kernel: one entry point of a pass's WGSL with its own group(0) layout; group(1) is
//! always the scene (`shaders/scene.wgsl`). Passes are small structs of these.

use super::scene::GpuScene;
use super::timing::Span;
use super::{Gpu, GpuError, LLVMPIPE_LOOP_LIMIT, shader};

/// The kind of resource at one group(0) binding, in binding order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// `var<storage, read>`
    Storage,
    /// `var<storage, read_write>`
    StorageReadWrite,
    /// `texture_2d<u32>`
    TextureUint,
}

impl Slot {
    fn ty(self) -> wgpu::BindingType {
        match self {
            Slot::Storage | Slot::StorageReadWrite => wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: self == Slot::Storage },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            Slot::TextureUint => wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Uint,
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
        }
    }
}

/// Compile a pass's WGSL (with the shared prelude for `scene`) inside an error scope.
pub fn module(gpu: &Gpu, scene: &GpuScene, label: &str, pass_wgsl: &str) -> Result<wgpu::ShaderModule, GpuError> {
    module_from_source(gpu, label, shader::source(pass_wgsl, scene.textured()))
}

/// Compile complete WGSL `source` inside an error scope.
pub fn module_from_source(gpu: &Gpu, label: &str, source: String) -> Result<wgpu::ShaderModule, GpuError> {
    gpu.build_checked(label, || {
        gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        })
    })
}

/// One compute pipeline and its group(0) layout.
pub struct Kernel {
    label: String,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl Kernel {
    /// Build entry point `entry` of `module` with group(0) made of `slots` and group(1) the scene.
    pub fn new(
        gpu: &Gpu,
        scene_layout: &wgpu::BindGroupLayout,
        module: &wgpu::ShaderModule,
        label: &str,
        entry: &str,
        slots: &[Slot],
    ) -> Result<Self, GpuError> {
        Self::with_constants(gpu, scene_layout, module, label, entry, slots, &[])
    }

    /// [`Kernel::new`] with values for the module's `override` constants.
    pub fn with_constants(
        gpu: &Gpu,
        scene_layout: &wgpu::BindGroupLayout,
        module: &wgpu::ShaderModule,
        label: &str,
        entry: &str,
        slots: &[Slot],
        constants: &[(&str, f64)],
    ) -> Result<Self, GpuError> {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = slots
            .iter()
            .enumerate()
            .map(|(i, s)| wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: s.ty(),
                count: None,
            })
            .collect();
        let (layout, pipeline) = gpu.build_checked(label, || {
            let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(&format!("{label}.layout")),
                entries: &entries,
            });
            let pipeline_layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(&format!("{label}.pipeline_layout")),
                bind_group_layouts: &[Some(&layout), Some(scene_layout)],
                immediate_size: 0,
            });
            let pipeline = gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(&format!("{label}.pipeline")),
                layout: Some(&pipeline_layout),
                module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
                cache: None,
            });
            (layout, pipeline)
        })?;
        Ok(Self { label: label.to_owned(), layout, pipeline })
    }

    /// Build pass `label` from `wgsl`: entry point `main` with group(0) `slots`, or, when
    /// `glossy`, `main_glossy` with `slots` followed by `glossy_slots` (the glossy buffers exist
    /// only then).
    pub fn pass(
        gpu: &Gpu,
        scene: &GpuScene,
        label: &str,
        wgsl: &str,
        slots: &[Slot],
        glossy_slots: &[Slot],
        glossy: bool,
    ) -> Result<Self, GpuError> {
        let m = module(gpu, scene, label, wgsl)?;
        let mut all = slots.to_vec();
        if glossy {
            all.extend_from_slice(glossy_slots);
        }
        Self::new(gpu, &scene.layout, &m, label, if glossy { "main_glossy" } else { "main" }, &all)
    }

    /// A group(0) bind group from resources in binding order.
    pub fn bind(&self, gpu: &Gpu, resources: &[wgpu::BindingResource<'_>]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = resources
            .iter()
            .enumerate()
            .map(|(i, r)| wgpu::BindGroupEntry { binding: i as u32, resource: r.clone() })
            .collect();
        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&format!("{}.bind_group", self.label)),
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// Record one dispatch in its own compute pass (with timestamps when given).
    pub fn dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        scene_group: &wgpu::BindGroup,
        workgroups: [u32; 3],
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(&self.label), timestamp_writes });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, group, &[]);
        pass.set_bind_group(1, scene_group, &[]);
        pass.dispatch_workgroups(workgroups[0], workgroups[1], workgroups[2]);
    }
}

/// Workgroups needed to cover `n` items in groups of `size`.
pub fn groups(n: u32, size: u32) -> u32 {
    n.div_ceil(size)
}

/// The pipelines of a pass whose invocations loop over every VAL (the gather, the brute
/// force), one per VAL range. GPUs take every VAL in one dispatch. A CPU adapter ends a
/// shader's loops after [`LLVMPIPE_LOOP_LIMIT`] iterations, silently, so there the VALs are
/// split into ranges that stay under it, one dispatch each, every range after the first
/// adding to what the earlier ones wrote. The shader takes its range from the `override`
/// constants `VAL_BEGIN` and `VAL_SPAN`.
pub struct ValRangeKernels {
    kernels: Vec<Kernel>,
    module: wgpu::ShaderModule,
    label: &'static str,
    entry: &'static str,
    slots: Vec<Slot>,
    /// VALs per range: `u32::MAX` on GPUs.
    range: u32,
}

impl ValRangeKernels {
    /// `tile_size`: VALs per workgroup-memory tile (one loop iteration per VAL and two per
    /// tile count toward the limit; a tile is kept spare).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        module: wgpu::ShaderModule,
        label: &'static str,
        entry: &'static str,
        slots: Vec<Slot>,
        tile_size: u32,
    ) -> Result<Self, GpuError> {
        let range = if gpu.is_cpu() { (LLVMPIPE_LOOP_LIMIT / (tile_size + 2) - 1) * tile_size } else { u32::MAX };
        let mut kernels = Self { kernels: Vec::new(), module, label, entry, slots, range };
        kernels.fit(gpu, scene, 1)?;
        Ok(kernels)
    }

    /// Make sure frames of up to `max_vals` VALs are covered whole: builds the pipelines of
    /// the ranges this needs that are not built yet (CPU adapters only).
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        let ranges = max_vals.div_ceil(self.range).max(1);
        for r in self.kernels.len() as u32..ranges {
            let constants: &[(&str, f64)] = if self.range == u32::MAX {
                &[]
            } else {
                &[("VAL_BEGIN", f64::from(r * self.range)), ("VAL_SPAN", f64::from(self.range))]
            };
            let kernel = Kernel::with_constants(
                gpu,
                &scene.layout,
                &self.module,
                self.label,
                self.entry,
                &self.slots,
                constants,
            )?;
            self.kernels.push(kernel);
        }
        Ok(())
    }

    /// Record every range's dispatch, in order; `span` times them together.
    pub fn dispatch(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        resources: &[wgpu::BindingResource<'_>],
        workgroups: [u32; 3],
        span: Option<Span<'_>>,
    ) {
        let parts = self.kernels.len();
        for (part, kernel) in self.kernels.iter().enumerate() {
            let group = kernel.bind(gpu, resources);
            let timestamps = span.as_ref().map(|s| s.compute_part(part, parts));
            kernel.dispatch(encoder, &group, &scene.bind_group, workgroups, timestamps);
        }
    }
}
