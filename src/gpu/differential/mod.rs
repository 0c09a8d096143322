//! Differential rendering onto real surfaces (`differential.wgsl` + the BVH traversal of
//! `references/bvh.wgsl`; after Debevec 1998 and Knecht et al., ISMAR 2010): per real
//! receiver point, the irradiance of the real VALs, the part of it the virtual meshes block and
//! the irradiance the virtual meshes' own sparse points add by reflection. `mr::differential`
//! makes the receivers from a depth frame and turns these sums into the composite. Rust twin:
//! [`twin::receiver_light`].
//!
//! Two kernels: `differential.wgsl` sums every VAL at every receiver with a shadow ray each (the
//! exact pass, [`Differential::run`]); `fast.wgsl` sums the VALs in groups ([`groups`]), a far
//! group as one VAL and without a ray where its cone misses the content (the fast pass,
//! [`Differential::run`] with [`Sums::Fast`], twin [`twin::receiver_light_fast`]).
//!
//! Both run in rounds, like the exact reference (see `differential.wgsl`): the host dispatches
//! until every receiver has seen every VAL. On CPU adapters they run on the CPU instead
//! ([`DifferentialDevice`]): the twins' sums over rayon's threads, each shadow ray decided by
//! obvhs's CWBVH traversal (`TraceBvh::blocked_mask`), which tests the same triangles with the
//! same arithmetic as the GPU layout's traversal but visits fewer nodes.

pub mod twin;

/// The VAL groups live with the twins (plain CPU data, which the twins sum).
pub use twin::groups;

use groups::{GroupedVals, ValGroup};
use twin::ContentSphere;

use crate::gpu::pass::{Entry, Kernel, PassDesc, Res, buffer, module_from_source, read, read_write};
use crate::gpu::raw::RawVal;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::shader::{ROUNDS, TILE_SIZE, WORKGROUP_SIZE};
use crate::gpu::{Gpu, GpuError, LLVMPIPE_LOOP_LIMIT};
use crate::twin::Val;
use crate::twin::bvh::{Occluders, ShadowTraversal, TraceBvh};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

pub use twin::{Receiver, ReceiverLight};

pub const WGSL: &str = include_str!("differential.wgsl");
pub const FAST_WGSL: &str = include_str!("fast.wgsl");
/// What both passes' WGSL share: the receivers, their sums and most bindings.
const RECEIVERS: &str = include_str!("receivers.wgsl");
const BVH: &str = include_str!("../references/bvh.wgsl");

/// Loop iterations (VAL loop and BVH traversal together) one invocation runs per round: below
/// llvmpipe's limit on all the loops of an invocation, with a margin (see `exact.wgsl`).
pub const DIFFERENTIAL_LOOP_BUDGET: u32 = 60_000;
const _: () = assert!(DIFFERENTIAL_LOOP_BUDGET < LLVMPIPE_LOOP_LIMIT);

/// The pass's own WGSL: its constant, the BVH traversal, the rounds' state, the shared
/// receivers, then `differential.wgsl`.
pub fn body() -> String {
    Wgsl::new()
        .u32("DIFFERENTIAL_LOOP_BUDGET", DIFFERENTIAL_LOOP_BUDGET)
        .include(BVH)
        .include(ROUNDS)
        .include(RECEIVERS)
        .include(WGSL)
        .finish()
}

/// The fast pass's WGSL: its constant, the BVH traversal, the rounds' state, the shared receivers,
/// then `fast.wgsl`.
pub fn fast_body() -> String {
    Wgsl::new()
        .u32("FAST_DIFFERENTIAL_LOOP_BUDGET", DIFFERENTIAL_LOOP_BUDGET)
        .include(BVH)
        .include(ROUNDS)
        .include(RECEIVERS)
        .include(FAST_WGSL)
        .finish()
}

/// The fast pass: [`PASS`]'s bindings (two progress words per receiver) and the groups.
pub const FAST_PASS: PassDesc = PassDesc {
    label: "differential_fast",
    bindings: &[
        read("params"),
        read("receivers"),
        read("vals"),
        read_write("light"),
        read("bvh_nodes"),
        read("bvh_triangles"),
        read_write("progress"),
        read_write("status"),
        read("groups"),
    ],
    entries: &[Entry::first("main", 9)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| FAST_PASS.source(&fast_body(), textured),
};

/// WGSL `FastParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawFastParams {
    pub receiver_count: u32,
    pub group_count: u32,
    /// `groups[.. real_groups]` hold real VALs, the rest re-emitters.
    pub real_groups: u32,
    /// [`Sums::Fast`]'s `ray_share`.
    pub ray_share: f32,
    /// The content's bounding sphere ([`ContentSphere`]): centre and radius.
    pub content: [f32; 4],
}

/// WGSL `ValGroup` ([`ValGroup`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawValGroup {
    pub position: [f32; 3],
    pub area: f32,
    pub normal: [f32; 3],
    pub radius: f32,
    pub flux: [f32; 3],
    pub reach: f32,
    pub first: u32,
    pub count: u32,
    pub representative: u32,
    pub shadow_reach: f32,
}

impl From<&ValGroup> for RawValGroup {
    fn from(g: &ValGroup) -> Self {
        let a = &g.aggregate;
        Self {
            position: a.position.into(),
            area: a.area,
            normal: a.normal.into(),
            radius: g.radius,
            flux: a.flux.into(),
            reach: g.reach,
            first: g.first,
            count: g.count,
            representative: g.representative,
            shadow_reach: g.shadow_reach,
        }
    }
}

/// One invocation per receiver: [`FAST_PASS`]'s bindings but the groups; `bvh_nodes` and
/// `bvh_triangles` sit at bindings 4 and 5, where `bvh.wgsl` declares them.
pub const PASS: PassDesc = PassDesc {
    label: "differential",
    bindings: FAST_PASS.bindings.split_at(8).0,
    entries: &[Entry::first("main", 8)],
    default_source: |textured| PASS.source(&body(), textured),
    ..FAST_PASS
};

/// WGSL `DifferentialParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawDifferentialParams {
    pub receiver_count: u32,
    /// `vals[.. real_count]` are the real VALs, the rest the virtual content's re-emitters.
    pub real_count: u32,
    pub val_count: u32,
    pub _pad0: u32,
}

/// WGSL `Receiver`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawReceiver {
    pub position: [f32; 3],
    pub _pad0: f32,
    pub normal: [f32; 3],
    pub _pad1: f32,
}

/// WGSL `ReceiverLight` (W/m², RGB; `w` unused).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawReceiverLight {
    pub unoccluded: [f32; 4],
    pub blocked: [f32; 4],
    pub added: [f32; 4],
}

impl From<&RawReceiverLight> for ReceiverLight {
    fn from(r: &RawReceiverLight) -> Self {
        let v = |c: [f32; 4]| Vec3::new(c[0], c[1], c[2]);
        Self { unoccluded: v(r.unoccluded), blocked: v(r.blocked), added: v(r.added) }
    }
}

/// Workgroups: 1-D [`WORKGROUP_SIZE`] on GPUs, one invocation on CPU adapters, for the reason
/// `references::exact` gives (llvmpipe counts its loop limit per SIMD vector, so diverging
/// lanes in the traversal share one limit).
fn workgroup(gpu: &Gpu) -> [u32; 3] {
    if gpu.is_cpu() { [1, 1, 1] } else { PASS.workgroup }
}

/// How the CPU backend traces a receiver's shadow rays to a group's members: one at a time, the
/// last blocker tested first. On the TUM replay (`examples/mr_differential.rs`, frames 0, 18
/// and 36, side by side) packets took 1.5x the time of single rays; single rays took 0.66x the
/// time of the GPU layout's traversal (`Bvh::occluded`, the backend before) in the exact pass and
/// 0.84x in the fast one (docs/measurements/differential.md).
const SHADOWS: ShadowTraversal = ShadowTraversal::Single;

/// `scene`'s triangles (the virtual meshes): vertex positions and corner indices.
fn scene_triangles(scene: &GpuScene) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let flat = &scene.flat;
    let positions = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    (positions, triangles)
}

/// `scene`'s triangles (the virtual meshes) with the GPU layout's tree over them.
pub fn scene_occluders(scene: &GpuScene) -> Occluders {
    let (positions, triangles) = scene_triangles(scene);
    Occluders::new(positions, triangles)
}

/// Where the differential pass runs (`settings.mr.device`), a setting of the scene.
pub use crate::scene::settings::DifferentialDevice;

/// The differential pass for one scene placement, on the GPU or the CPU.
pub struct Differential {
    backend: Backend,
}

#[allow(clippy::large_enum_variant)]
enum Backend {
    Gpu(GpuPass),
    /// The virtual triangles' CPU hierarchy (obvhs's CWBVH), which decides each shadow ray as
    /// `Bvh::occluded` does, by the same triangle test, faster.
    Cpu(TraceBvh),
}

impl Differential {
    /// The pass over `scene`'s triangles as placed now, on [`DifferentialDevice::Auto`].
    pub fn new(gpu: &Gpu, scene: &GpuScene) -> Result<Self, GpuError> {
        Self::on(gpu, scene, DifferentialDevice::Auto)
    }

    /// The pass over `scene`'s triangles as placed now, on `device`.
    pub fn on(gpu: &Gpu, scene: &GpuScene, device: DifferentialDevice) -> Result<Self, GpuError> {
        let cpu = match device {
            DifferentialDevice::Auto => gpu.is_cpu(),
            DifferentialDevice::Gpu => false,
            DifferentialDevice::Cpu => true,
        };
        let backend = if cpu {
            let (positions, triangles) = scene_triangles(scene);
            Backend::Cpu(TraceBvh::build(&positions, &triangles))
        } else {
            Backend::Gpu(GpuPass::new(gpu, scene)?)
        };
        Ok(Self { backend })
    }

    /// Where it runs.
    pub fn device(&self) -> DifferentialDevice {
        match self.backend {
            Backend::Gpu(_) => DifferentialDevice::Gpu,
            Backend::Cpu(_) => DifferentialDevice::Cpu,
        }
    }

    /// The sums of `sums` at every receiver (see [`Sums`]). Returns them and the GPU rounds it
    /// took (0 on the CPU). Submits and waits.
    pub fn run(
        &mut self,
        gpu: &Gpu,
        scene: &GpuScene,
        receivers: &[Receiver],
        sums: Sums<'_>,
    ) -> Result<(Vec<ReceiverLight>, u32), GpuError> {
        match &mut self.backend {
            Backend::Gpu(_) if receivers.is_empty() => Ok((Vec::new(), 0)),
            Backend::Gpu(pass) => {
                let bound = pass.bind(gpu, scene, receivers, sums)?;
                pass.rounds(gpu, scene, &bound, receivers.len())
            }
            Backend::Cpu(bvh) => Ok((cpu_sums(bvh, receivers, sums), 0)),
        }
    }
}

/// [`Differential::run`] on the CPU cores, a receiver per task.
fn cpu_sums(bvh: &TraceBvh, receivers: &[Receiver], sums: Sums<'_>) -> Vec<ReceiverLight> {
    use rayon::prelude::*;
    let blocked = |origin, targets: &[Vec3]| bvh.blocked_mask(origin, targets, SHADOWS);
    match sums {
        Sums::Exact { vals, real_count } => {
            let real_count = real_count.min(vals.len());
            let light = |r| twin::receiver_light_with(r, vals, real_count, blocked);
            receivers.par_iter().map(light).collect()
        }
        Sums::Fast { grouped, content, ray_share } => {
            let light = |r| twin::receiver_light_fast_with(r, grouped, content, ray_share, blocked);
            receivers.par_iter().map(light).collect()
        }
    }
}

/// What the differential pass sums at each receiver.
#[derive(Clone, Copy)]
pub enum Sums<'a> {
    /// Every VAL ([`twin::receiver_light`]): `vals[.. real_count]` are the real VALs, the rest
    /// the virtual content's re-emitters.
    Exact { vals: &'a [Val], real_count: usize },
    /// The VALs in groups ([`twin::receiver_light_fast`]), real VALs and re-emitters, with
    /// `content` the virtual content's bounding sphere; a group's members that light a receiver
    /// with less than `ray_share` of its estimated irradiance share one shadow ray.
    Fast { grouped: &'a GroupedVals, content: &'a ContentSphere, ray_share: f32 },
}

/// A frame's bind group, for the kernel it was bound to.
enum Bound {
    Exact(wgpu::BindGroup),
    Fast(wgpu::BindGroup),
}

/// The GPU passes for one scene placement: the BVH, the exact kernel, the fast one (built on its
/// first use) and buffers grown to the largest frame so far.
struct GpuPass {
    kernel: Kernel,
    fast: Option<Kernel>,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    params: wgpu::Buffer,
    fast_params: wgpu::Buffer,
    status: wgpu::Buffer,
    /// (receivers, light, progress with two words per receiver) and their capacity in receivers.
    per_receiver: Option<(wgpu::Buffer, wgpu::Buffer, wgpu::Buffer, usize)>,
    /// VAL buffer and its capacity.
    vals: Option<(wgpu::Buffer, usize)>,
    /// Group buffer and its capacity.
    groups: Option<(wgpu::Buffer, usize)>,
}

impl GpuPass {
    /// Build the BVH of `scene`'s triangles as placed now and the exact pass.
    fn new(gpu: &Gpu, scene: &GpuScene) -> Result<Self, GpuError> {
        let bvh = scene_occluders(scene).bvh;
        let none = wgpu::BufferUsages::empty();
        // A zero-filled node ends the traversal at once; a binding cannot be empty.
        let nodes = if bvh.nodes.is_empty() { vec![Default::default()] } else { bvh.nodes };
        let order = if bvh.order.is_empty() { vec![0] } else { bvh.order };
        let nodes = gpu.storage_buffer("differential.bvh_nodes", &nodes, none)?;
        let order = gpu.storage_buffer("differential.bvh_triangles", &order, none)?;
        let kernel = build_kernel(gpu, scene, &PASS, &body())?;
        let params = gpu.storage_buffer("differential.params", &[RawDifferentialParams::default()], none)?;
        let fast_params = gpu.storage_buffer("differential.fast_params", &[RawFastParams::default()], none)?;
        let status = gpu.storage_buffer_sized::<u32>("differential.status", 2)?;
        Ok(Self {
            kernel,
            fast: None,
            nodes,
            order,
            params,
            fast_params,
            status,
            per_receiver: None,
            vals: None,
            groups: None,
        })
    }

    /// Size the per-receiver buffers for `receivers` and the VAL buffer for `vals`, and upload
    /// both.
    fn upload(&mut self, gpu: &Gpu, receivers: &[Receiver], vals: &[Val]) -> Result<(), GpuError> {
        let n = receivers.len();
        if self.per_receiver.as_ref().is_none_or(|p| p.3 < n) {
            let receivers = gpu.storage_buffer_sized::<RawReceiver>("differential.receivers", n)?;
            let light = gpu.storage_buffer_sized::<RawReceiverLight>("differential.light", n)?;
            let progress = gpu.storage_buffer_sized::<u32>("differential.progress", 2 * n)?;
            self.per_receiver = Some((receivers, light, progress, n));
        }
        let val_slots = vals.len().max(1);
        if self.vals.as_ref().is_none_or(|v| v.1 < val_slots) {
            self.vals = Some((gpu.storage_buffer_sized::<RawVal>("differential.vals", val_slots)?, val_slots));
        }
        let raw: Vec<RawReceiver> = receivers
            .iter()
            .map(|r| RawReceiver { position: r.position.into(), normal: r.normal.into(), ..Default::default() })
            .collect();
        gpu.queue.write_buffer(&self.per_receiver.as_ref().expect("made above").0, 0, bytemuck::cast_slice(&raw));
        if !vals.is_empty() {
            let raw: Vec<RawVal> = vals.iter().map(RawVal::from).collect();
            gpu.queue.write_buffer(&self.vals.as_ref().expect("made above").0, 0, bytemuck::cast_slice(&raw));
        }
        Ok(())
    }

    /// Upload `receivers` and what `sums` sums, and bind the kernel that sums it (building the
    /// fast one on its first use).
    fn bind(&mut self, gpu: &Gpu, scene: &GpuScene, receivers: &[Receiver], sums: Sums<'_>) -> Result<Bound, GpuError> {
        Ok(match sums {
            Sums::Exact { vals, real_count } => {
                self.upload(gpu, receivers, vals)?;
                let params = RawDifferentialParams {
                    receiver_count: receivers.len() as u32,
                    real_count: real_count.min(vals.len()) as u32,
                    val_count: vals.len() as u32,
                    _pad0: 0,
                };
                gpu.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
                Bound::Exact(self.kernel.bind(gpu, &self.resources(&self.params)))
            }
            Sums::Fast { grouped, content, ray_share } => {
                if self.fast.is_none() {
                    self.fast = Some(build_kernel(gpu, scene, &FAST_PASS, &fast_body())?);
                }
                self.upload(gpu, receivers, &grouped.vals)?;
                let slots = grouped.groups.len().max(1);
                if self.groups.as_ref().is_none_or(|g| g.1 < slots) {
                    let buffer = gpu.storage_buffer_sized::<RawValGroup>("differential.groups", slots)?;
                    self.groups = Some((buffer, slots));
                }
                let groups = &self.groups.as_ref().expect("made above").0;
                if !grouped.groups.is_empty() {
                    let raw: Vec<RawValGroup> = grouped.groups.iter().map(RawValGroup::from).collect();
                    gpu.queue.write_buffer(groups, 0, bytemuck::cast_slice(&raw));
                }
                let params = RawFastParams {
                    receiver_count: receivers.len() as u32,
                    group_count: grouped.groups.len() as u32,
                    real_groups: grouped.real_groups as u32,
                    ray_share,
                    content: content.centre.extend(content.radius).into(),
                };
                gpu.queue.write_buffer(&self.fast_params, 0, bytemuck::bytes_of(&params));
                let kernel = self.fast.as_ref().expect("built above");
                let mut resources = self.resources(&self.fast_params);
                resources.push(buffer("groups", groups));
                Bound::Fast(kernel.bind(gpu, &resources))
            }
        })
    }

    /// The resources both passes bind (all of [`PASS`]'s, the fast pass's groups aside), with
    /// `params` at binding 0; after an upload.
    fn resources<'a>(&'a self, params: &'a wgpu::Buffer) -> Vec<Res<'a>> {
        let (receivers, light, progress, _) = self.per_receiver.as_ref().expect("uploaded");
        vec![
            buffer("params", params),
            buffer("receivers", receivers),
            buffer("vals", &self.vals.as_ref().expect("uploaded").0),
            buffer("light", light),
            buffer("bvh_nodes", &self.nodes),
            buffer("bvh_triangles", &self.order),
            buffer("progress", progress),
            buffer("status", &self.status),
        ]
    }

    /// Dispatch the bound kernel over `n` receivers until every one is done, then read their
    /// sums; the GPU rounds it took.
    fn rounds(
        &self,
        gpu: &Gpu,
        scene: &GpuScene,
        bound: &Bound,
        n: usize,
    ) -> Result<(Vec<ReceiverLight>, u32), GpuError> {
        let (kernel, group) = match bound {
            Bound::Exact(group) => (&self.kernel, group),
            Bound::Fast(group) => (self.fast.as_ref().expect("built by bind"), group),
        };
        let (_, light, progress, _) = self.per_receiver.as_ref().expect("uploaded");
        let mut rounds = 0;
        loop {
            let mut encoder = gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("differential.round") });
            if rounds == 0 {
                encoder.clear_buffer(progress, 0, Some(8 * n as u64));
            }
            encoder.clear_buffer(&self.status, 0, None);
            kernel.dispatch(&mut encoder, group, scene, [n as u32, 1, 1], None);
            gpu.submit_and_wait(encoder)?;
            rounds += 1;
            if crate::gpu::rounds_done(gpu, &self.status, rounds, "differential: receivers", DIFFERENTIAL_LOOP_BUDGET)?
            {
                break;
            }
        }
        let out = gpu.read_buffer::<RawReceiverLight>(light, n)?;
        Ok((out.iter().map(ReceiverLight::from).collect(), rounds))
    }
}

/// The kernel of `desc` with its WGSL `body`, at this adapter's workgroup size.
fn build_kernel(gpu: &Gpu, scene: &GpuScene, desc: &PassDesc, body: &str) -> Result<Kernel, GpuError> {
    let workgroup = workgroup(gpu);
    let source = desc.source_with(body, scene.textured(), workgroup, TILE_SIZE);
    let module = module_from_source(gpu, desc.label, source)?;
    Kernel::build(gpu, scene, desc, &module, desc.entry("main"), &[], workgroup)
}
