//! A compute pass: one entry point of a WGSL module with its own group(0) layout; group(1) is
//! always the scene (`shader/scene.wgsl`).
//!
//! A pass states once, in a [`PassDesc`], the names and kinds of its group(0) bindings (the
//! WGSL variables' names, in binding order), its entry points and its workgroup size. The
//! workgroup size reaches the shader as `WORKGROUP_X/Y/Z` in the generated header, the layout is
//! built from the bindings, and every dispatch names the resources it binds
//! ([`Kernel::run`]), so a resource cannot land at the wrong binding. A naga test
//! (`tests/integration/layout.rs`) checks every [`PassDesc`] of [`crate::gpu::passes`] against
//! what each entry point of its WGSL really uses.

use super::scene::GpuScene;
use super::timing::Span;
use super::{Gpu, GpuError, LLVMPIPE_LOOP_LIMIT, shader};

/// The kind of resource at one group(0) binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// `var<storage, read>`
    Storage,
    /// `var<storage, read_write>`
    StorageReadWrite,
    /// `texture_2d<u32>`
    TextureUint,
    /// `texture_2d<f32>` bound to a depth texture's view as unfilterable float: `textureLoad`
    /// of a `texture_depth_2d` has no GLSL translation (wgpu's GL backend refuses the pipeline),
    /// while a float texture loads on every backend and gives the same depth.
    DepthAsFloat,
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
            Slot::DepthAsFloat => wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
        }
    }
}

/// One group(0) binding: the WGSL variable's name and its kind. Its index is its place in
/// [`PassDesc::bindings`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    pub name: &'static str,
    pub slot: Slot,
}

/// `var<storage, read> name`
pub const fn read(name: &'static str) -> Binding {
    Binding { name, slot: Slot::Storage }
}

/// `var<storage, read_write> name`
pub const fn read_write(name: &'static str) -> Binding {
    Binding { name, slot: Slot::StorageReadWrite }
}

/// `var name: texture_2d<u32>`
pub const fn texture(name: &'static str) -> Binding {
    Binding { name, slot: Slot::TextureUint }
}

/// `var name: texture_2d<f32>`, bound to a depth texture's depth-only view ([`Slot::DepthAsFloat`]).
pub const fn depth_texture(name: &'static str) -> Binding {
    Binding { name, slot: Slot::DepthAsFloat }
}

/// An entry point and the pass's bindings it uses: the first `bindings` of them, but those
/// named in `except`.
#[derive(Clone, Copy, Debug)]
pub struct Entry {
    pub name: &'static str,
    pub bindings: usize,
    pub except: &'static [&'static str],
}

impl Entry {
    /// `name`, using the pass's first `bindings` bindings.
    pub const fn first(name: &'static str, bindings: usize) -> Self {
        Self { name, bindings, except: &[] }
    }

    /// The bindings it uses, with their indices (the WGSL `@binding`s).
    pub fn uses(&self, desc: &PassDesc) -> Vec<(u32, Binding)> {
        desc.bindings[..self.bindings]
            .iter()
            .enumerate()
            .filter(|(_, b)| !self.except.contains(&b.name))
            .map(|(i, b)| (i as u32, *b))
            .collect()
    }
}

/// What a pass declares about its shader.
#[derive(Clone, Copy, Debug)]
pub struct PassDesc {
    /// Labels of the pass's objects are `"<label>.<object>"`.
    pub label: &'static str,
    /// Group(0), in binding order.
    pub bindings: &'static [Binding],
    pub entries: &'static [Entry],
    /// Invocations per workgroup, handed to the shader as `WORKGROUP_X/Y/Z`.
    pub workgroup: [u32; 3],
    /// The pass's complete WGSL at its default parameters (what the layout test parses).
    pub default_source: fn(textured: bool) -> String,
}

impl PassDesc {
    /// The entry point named `name`.
    pub fn entry(&self, name: &str) -> Entry {
        *self.entries.iter().find(|e| e.name == name).unwrap_or_else(|| panic!("{}: no entry point {name}", self.label))
    }

    /// The usual entry for a pass with a glossy variant: `main_glossy` when `glossy`, else `main`.
    pub fn lobe_entry(&self, glossy: bool) -> Entry {
        self.entry(if glossy { "main_glossy" } else { "main" })
    }

    /// The complete WGSL of a pass whose own file is `body`, for a scene that is `textured` or
    /// not, with this pass's workgroup size.
    pub fn source(&self, body: &str, textured: bool) -> String {
        self.source_with(body, textured, self.workgroup, shader::TILE_SIZE)
    }

    /// [`PassDesc::source`] with another workgroup size and tile size (the bench's variants,
    /// the exact pass's CPU-adapter workgroups).
    pub fn source_with(&self, body: &str, textured: bool, workgroup: [u32; 3], tile_size: u32) -> String {
        let [x, y, z] = workgroup;
        let sizes = shader::Wgsl::new().u32("WORKGROUP_X", x).u32("WORKGROUP_Y", y).u32("WORKGROUP_Z", z);
        shader::prelude(sizes, textured, tile_size).include(body).finish()
    }
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

/// A resource bound by name for one dispatch.
pub struct Res<'a> {
    pub name: &'static str,
    pub resource: wgpu::BindingResource<'a>,
}

/// The whole of `buffer` at the binding `name`.
pub fn buffer<'a>(name: &'static str, buffer: &'a wgpu::Buffer) -> Res<'a> {
    Res { name, resource: buffer.as_entire_binding() }
}

/// `view` at the binding `name`.
pub fn view<'a>(name: &'static str, view: &'a wgpu::TextureView) -> Res<'a> {
    Res { name, resource: wgpu::BindingResource::TextureView(view) }
}

/// `fixed` followed by the diffuse buffer of each of `lobes` under its first name and then,
/// when the lobes have their glossy buffers, each glossy buffer under its second name: the
/// binding order of every pass with a glossy variant.
pub fn with_lobes<'a>(
    mut fixed: Vec<Res<'a>>,
    lobes: &[(&'a super::Lobes, &'static str, &'static str)],
) -> Vec<Res<'a>> {
    fixed.extend(lobes.iter().map(|(l, diffuse, _)| buffer(diffuse, &l.diffuse)));
    if lobes.iter().all(|(l, _, _)| l.glossy.is_some()) {
        fixed.extend(lobes.iter().filter_map(|(l, _, glossy)| l.glossy.as_ref().map(|b| buffer(glossy, b))));
    }
    fixed
}

/// One compute pipeline: an entry point of a pass with its group(0) layout.
pub struct Kernel {
    label: String,
    bindings: Vec<(u32, Binding)>,
    workgroup: [u32; 3],
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl Kernel {
    /// Build `entry` of `desc` from the compiled `module` (made from [`PassDesc::source`] with
    /// `workgroup`, usually `desc.workgroup`), with values for the module's `override` constants.
    pub fn build(
        gpu: &Gpu,
        scene: &GpuScene,
        desc: &PassDesc,
        module: &wgpu::ShaderModule,
        entry: Entry,
        constants: &[(&str, f64)],
        workgroup: [u32; 3],
    ) -> Result<Self, GpuError> {
        let label = if desc.entries.len() > 1 && !entry.name.starts_with("main") {
            format!("{}.{}", desc.label, entry.name)
        } else {
            desc.label.to_owned()
        };
        let bindings = entry.uses(desc);
        let entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
            .iter()
            .map(|(i, b)| wgpu::BindGroupLayoutEntry {
                binding: *i,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: b.slot.ty(),
                count: None,
            })
            .collect();
        let (layout, pipeline) = gpu.build_checked(&label, || {
            let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(&format!("{label}.layout")),
                entries: &entries,
            });
            let pipeline_layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(&format!("{label}.pipeline_layout")),
                bind_group_layouts: &[Some(&layout), Some(&scene.layout)],
                immediate_size: 0,
            });
            let pipeline = gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(&format!("{label}.pipeline")),
                layout: Some(&pipeline_layout),
                module,
                entry_point: Some(entry.name),
                compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
                cache: None,
            });
            (layout, pipeline)
        })?;
        Ok(Self { label, bindings, workgroup, layout, pipeline })
    }

    /// A group(0) bind group from `resources`, which must name this kernel's bindings in order.
    pub fn bind(&self, gpu: &Gpu, resources: &[Res<'_>]) -> wgpu::BindGroup {
        let names: Vec<&str> = resources.iter().map(|r| r.name).collect();
        let wanted: Vec<&str> = self.bindings.iter().map(|(_, b)| b.name).collect();
        assert_eq!(names, wanted, "{}: resources bound out of order or missing", self.label);
        let entries: Vec<wgpu::BindGroupEntry> = resources
            .iter()
            .zip(&self.bindings)
            .map(|(r, (i, _))| wgpu::BindGroupEntry { binding: *i, resource: r.resource.clone() })
            .collect();
        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&format!("{}.bind_group", self.label)),
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// Record one dispatch covering `invocations` in its own compute pass, with `group` from
    /// [`Kernel::bind`] (timestamps when given).
    pub fn dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        scene: &GpuScene,
        invocations: [u32; 3],
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        self.dispatch_on(encoder, group, &scene.bind_group, invocations, timestamp_writes);
    }

    /// [`Kernel::dispatch`] with `scene_group` as group(1): the scene with other triangles over
    /// the same vertices (the camera's simplified copy, [`GpuScene::camera_triangles`]).
    pub fn dispatch_on(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        scene_group: &wgpu::BindGroup,
        invocations: [u32; 3],
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(&self.label), timestamp_writes });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, group, &[]);
        pass.set_bind_group(1, scene_group, &[]);
        let [x, y, z] = std::array::from_fn(|i| invocations[i].div_ceil(self.workgroup[i]));
        pass.dispatch_workgroups(x, y, z);
    }
}

/// What a pass runs: one kernel, or, for a pass whose invocations loop over every VAL (the
/// gather, the brute force), one kernel per VAL range. GPUs take every VAL in one dispatch. A
/// CPU adapter ends a shader's loops after [`LLVMPIPE_LOOP_LIMIT`] iterations, silently, so
/// there the VALs are split into ranges that stay under it, one dispatch each, every range
/// after the first adding to what the earlier ones wrote. The shader takes its range from the
/// `override` constants `VAL_BEGIN` and `VAL_SPAN` (`shader/val_tiles.wgsl`).
pub struct Kernels {
    kernels: Vec<Kernel>,
    /// How to build more ranges; `None` for a pass of one kernel.
    ranges: Option<ValRanges>,
}

struct ValRanges {
    module: wgpu::ShaderModule,
    desc: &'static PassDesc,
    entry: Entry,
    workgroup: [u32; 3],
    /// VALs per range: `u32::MAX` on GPUs.
    range: u32,
}

impl Kernels {
    /// Compile `body` for `desc` and build its entry for the scene's lobes: `main_glossy` when
    /// `glossy`, else `main`. The common case of a pass with one kernel.
    pub fn lobes(gpu: &Gpu, scene: &GpuScene, desc: &PassDesc, body: &str, glossy: bool) -> Result<Self, GpuError> {
        Self::entry(gpu, scene, desc, body, desc.lobe_entry(glossy))
    }

    /// Compile `body` for `desc` and build its `entry`, one kernel.
    pub fn entry(gpu: &Gpu, scene: &GpuScene, desc: &PassDesc, body: &str, entry: Entry) -> Result<Self, GpuError> {
        let module = module_from_source(gpu, desc.label, desc.source(body, scene.textured()))?;
        let kernel = Kernel::build(gpu, scene, desc, &module, entry, &[], desc.workgroup)?;
        Ok(Self { kernels: vec![kernel], ranges: None })
    }

    /// `entry` of `desc` compiled as `source` with `workgroup`, in VAL ranges; `tile_size`: VALs
    /// per workgroup-memory tile (one loop iteration per VAL and two per tile count toward the
    /// limit; a tile is kept spare).
    pub fn val_ranges(
        gpu: &Gpu,
        scene: &GpuScene,
        desc: &'static PassDesc,
        source: String,
        entry: Entry,
        workgroup: [u32; 3],
        tile_size: u32,
    ) -> Result<Self, GpuError> {
        let module = module_from_source(gpu, desc.label, source)?;
        let range = if gpu.is_cpu() { (LLVMPIPE_LOOP_LIMIT / (tile_size + 2) - 1) * tile_size } else { u32::MAX };
        let ranges = ValRanges { module, desc, entry, workgroup, range };
        let mut kernels = Self { kernels: Vec::new(), ranges: Some(ranges) };
        kernels.fit(gpu, scene, 1)?;
        Ok(kernels)
    }

    /// Make sure frames of up to `max_vals` VALs are covered whole: builds the pipelines of
    /// the VAL ranges this needs that are not built yet (CPU adapters only).
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        let Some(r) = &self.ranges else {
            return Ok(());
        };
        for i in self.kernels.len() as u32..max_vals.div_ceil(r.range).max(1) {
            let constants: &[(&str, f64)] = if r.range == u32::MAX {
                &[]
            } else {
                &[("VAL_BEGIN", f64::from(i * r.range)), ("VAL_SPAN", f64::from(r.range))]
            };
            let kernel = Kernel::build(gpu, scene, r.desc, &r.module, r.entry, constants, r.workgroup)?;
            self.kernels.push(kernel);
        }
        Ok(())
    }

    /// Bind `resources` and dispatch over `invocations` (every range in order), timed by
    /// `span` as one stage (or its share of one: [`Span::share`]): one call per dispatch.
    pub fn run(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        resources: &[Res<'_>],
        invocations: [u32; 3],
        span: Option<Span<'_>>,
    ) {
        self.run_on(gpu, encoder, &scene.bind_group, resources, invocations, span);
    }

    /// [`Kernels::run`] with `scene_group` as group(1) ([`Kernel::dispatch_on`]).
    pub fn run_on(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene_group: &wgpu::BindGroup,
        resources: &[Res<'_>],
        invocations: [u32; 3],
        span: Option<Span<'_>>,
    ) {
        for (part, kernel) in self.kernels.iter().enumerate() {
            let group = kernel.bind(gpu, resources);
            let timestamps = span.as_ref().and_then(|s| s.compute_part(part, self.kernels.len()));
            kernel.dispatch_on(encoder, &group, scene_group, invocations, timestamps);
        }
    }

    /// How many dispatches [`Kernels::run`] makes.
    pub fn len(&self) -> usize {
        self.kernels.len()
    }

    /// Whether it has no kernel (never: every constructor builds one).
    pub fn is_empty(&self) -> bool {
        self.kernels.is_empty()
    }
}
