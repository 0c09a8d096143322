//! The GPU side: one headless device, the scene's buffers, and the techniques, one folder each
//! (`lights/`, `raster/`, `sparse/`, `visibility/`, `references/`), each pass's WGSL beside its
//! Rust module. A technique ([`technique::Technique`]) prepares its resources and records its
//! passes; the renderer (`renderer`) runs the list of techniques a frame needs.
//!
//! Every pass declares its bindings, entry points and workgroup size once in a
//! [`pass::PassDesc`] (checked against its WGSL by naga in `tests/integration/layout.rs`), owns
//! its pipeline(s) and records each dispatch with one call that names its resources
//! ([`pass::Kernel::run`]). Passes that have a glossy variant have two entry points, `main` and
//! `main_glossy`; the glossy buffers are bound only by the latter and exist only when the scene
//! has a glossy material. Shared WGSL (structs, the docs/design.md formulas, the scene bindings) is
//! in `shader/`.

pub mod differential;
pub mod lights;
pub mod pass;
pub mod raster;
/// The `#[repr(C)]` twins of the WGSL structs (`twin::raw`, beside the CPU twins that convert
/// to and from them).
pub use crate::twin::raw;
pub mod references;
pub mod scene;
pub mod shader;
pub mod sparse;
pub mod technique;
pub mod timing;
pub mod visibility;

use bytemuck::Pod;

/// Every compute pass's declaration, in frame order: what the naga layout test checks against
/// the WGSL (`tests/integration/layout.rs`) and the shaders the compilation test builds. The
/// visibility modes' come from their folders, through the registry of modes.
pub fn passes() -> Vec<&'static pass::PassDesc> {
    let mut passes = LIGHT_PASSES.to_vec();
    passes.extend(visibility::passes());
    passes.extend(SHADING_PASSES);
    passes
}

/// The passes making VALs and the second bounce's points.
const LIGHT_PASSES: &[&pass::PassDesc] = &[
    &lights::rsm::PASS,
    &lights::light_rsms::PASS,
    &lights::rgbd::PASS,
    &lights::bounce::POINTS,
    &lights::bounce::GROUPED_POINTS,
    &lights::bounce::DISK_POINTS,
    &lights::bounce::OCCLUSION,
    &lights::bounce::VISIBILITY,
    &lights::bounce::ISM_VISIBILITY,
    &lights::bounce::DRAW,
];

/// The passes shading receivers and the references'.
const SHADING_PASSES: &[&pass::PassDesc] = &[
    &sparse::gather::PASS,
    &sparse::gather::GROUPED_PASS,
    &sparse::gather::CHOSEN_PASS,
    &sparse::gather::CHOSEN_GROUPED_PASS,
    &sparse::adaptive::PASS,
    &sparse::renormalise::PASS,
    &sparse::interpolate::PASS,
    &sparse::interpolate::ADAPTIVE_PASS,
    &sparse::shade::PASS,
    &sparse::near_field::GRID,
    &sparse::near_field::SHADE,
    &sparse::near_field::FILTER,
    &references::brute_force::PASS,
    &references::brute_force::GROUPED_PASS,
    &references::brute_force::ISM_VISIBILITY,
    &references::brute_force::IN_PASS_RASTER,
    &references::brute_force::IN_PASS_ISM,
    &references::exact::PASS,
    &references::estimator::PASS,
    &lights::direct::PASS,
    &lights::many::PASS,
    &differential::PASS,
    &differential::FAST_PASS,
];

/// Errors from the device and from pipeline creation.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (is a Vulkan driver installed? try `apt-get install mesa-vulkan-drivers libvulkan1`): {0}"
    )]
    NoAdapter(#[from] wgpu::RequestAdapterError),
    #[error("could not open the GPU device: {0}")]
    Device(#[from] wgpu::RequestDeviceError),
    #[error("shader or pipeline `{label}` failed to build: {message}")]
    Pipeline { label: String, message: String },
    #[error("waiting for the GPU failed: {0}")]
    Poll(#[from] wgpu::PollError),
    #[error("mapping a readback buffer failed: {0}")]
    Map(String),
    #[error("{what} needs {needed} bytes, over the device limit of {limit}")]
    TooLarge { what: String, needed: u64, limit: u64 },
    #[error("RGB-D frame does not fit: {0}")]
    FrameMismatch(String),
    #[error("GPU work did not finish: {0}")]
    Incomplete(String),
    #[error("not supported: {0}")]
    Unsupported(String),
}

/// `RELUME_GATHER_LANES`, when set: a power of two from 1 to [`sparse::gather::MAX_LANES`].
fn gather_lanes_from_env() -> Result<Option<u32>, GpuError> {
    let Ok(text) = std::env::var("RELUME_GATHER_LANES") else {
        return Ok(None);
    };
    match text.trim().parse::<u32>() {
        Ok(n) if n.is_power_of_two() && n <= sparse::gather::MAX_LANES => Ok(Some(n)),
        _ => Err(GpuError::Unsupported(format!(
            "RELUME_GATHER_LANES: expected a power of two from 1 to {}, got `{text}`",
            sparse::gather::MAX_LANES
        ))),
    }
}

/// Loop iterations after which llvmpipe (lavapipe) ends every loop of a shader invocation,
/// silently: `LP_MAX_TGSI_LOOP_ITERATIONS` in Mesa's gallivm, "shared between every loop in a
/// shader" and counted per SIMD vector of invocations. Passes whose loops can run longer must
/// split their work into rounds ([`rounds_done`]: the exact reference, the differential pass).
pub const LLVMPIPE_LOOP_LIMIT: u32 = 65_535;

/// Rounds at most before a pass that runs in rounds gives up (each makes progress on every
/// unfinished item, so only a driver that ignores the loop budget could need this many).
const MAX_ROUNDS: u32 = 1 << 16;

/// After `rounds` rounds of a pass that runs in rounds under llvmpipe's loop limit (the exact
/// reference, the differential pass): whether its `status` buffer (`[left, stuck]`, the items
/// unfinished and those of them that made no progress) says every item is done. An item that
/// made no progress, or more than [`MAX_ROUNDS`] rounds, is an error naming `what` (e.g.
/// "exact visibility: pixels") and the per-round loop `budget`.
pub(crate) fn rounds_done(
    gpu: &Gpu,
    status: &wgpu::Buffer,
    rounds: u32,
    what: &str,
    budget: u32,
) -> Result<bool, GpuError> {
    let [left, stuck] = gpu.read_buffer::<u32>(status, 2)?[..] else {
        unreachable!("read_buffer returns the 2 elements asked for")
    };
    if left == 0 {
        return Ok(true);
    }
    if stuck > 0 || rounds >= MAX_ROUNDS {
        return Err(GpuError::Incomplete(format!(
            "{what}: {left} unfinished after {rounds} rounds, {stuck} of them made no progress (a shadow ray \
             longer than {budget} BVH steps)"
        )));
    }
    Ok(false)
}

/// A pair of per-lobe buffers: the diffuse one always, the glossy one only when the scene has a
/// glossy material.
pub struct Lobes {
    pub diffuse: wgpu::Buffer,
    pub glossy: Option<wgpu::Buffer>,
}

impl Lobes {
    /// `count` elements of `T` per lobe, labelled `<label>_diffuse` / `<label>_glossy`.
    pub fn new<T: Pod>(gpu: &Gpu, label: &str, count: usize, glossy: bool) -> Result<Self, GpuError> {
        Ok(Self {
            diffuse: gpu.storage_buffer_sized::<T>(&format!("{label}_diffuse"), count)?,
            glossy: if glossy { Some(gpu.storage_buffer_sized::<T>(&format!("{label}_glossy"), count)?) } else { None },
        })
    }
}

/// Device memory in buffers and textures at one moment ([`Gpu::memory_in_use`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct MemoryInUse {
    pub buffer_bytes: u64,
    pub texture_bytes: u64,
}

impl MemoryInUse {
    pub fn total_bytes(&self) -> u64 {
        self.buffer_bytes + self.texture_bytes
    }
}

/// The device, its queue and what the adapter can do. Owned by one thread; passes borrow it.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    /// Whether GPU timestamp queries (inside encoders) are available.
    pub timestamps: bool,
    /// Invocations per sparse point in the gather, when not the adapter's default
    /// (`sparse::gather::lanes_for`): `RELUME_GATHER_LANES`, for measuring the gather side by
    /// side on a device and for running the GPUs' kernel on a CPU adapter in tests.
    pub gather_lanes: Option<u32>,
}

impl Gpu {
    /// Open the first adapter headlessly (backend choice honours `WGPU_BACKEND`).
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(None))
    }

    /// Open adapter `index` of [`Gpu::adapters`] (the service's `--adapters`: one device per
    /// GPU); [`GpuError::Unsupported`] when there are not that many.
    pub fn on_adapter(index: usize) -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(Some(index)))
    }

    /// The adapters found (backends as `WGPU_BACKEND` says), most capable first: discrete,
    /// integrated, virtual, CPU, other; in the driver's order among equals.
    pub fn adapters() -> Vec<wgpu::AdapterInfo> {
        pollster::block_on(Self::sorted_adapters(&Self::instance())).iter().map(wgpu::Adapter::get_info).collect()
    }

    fn instance() -> wgpu::Instance {
        // Debug markers and validation layers are opt-in (WGPU_DEBUG=1, WGPU_VALIDATION=1): Mesa
        // 22's lavapipe crashes in vkCmdBeginDebugUtilsLabelEXT, which wgpu's debug builds use.
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.flags = wgpu::InstanceFlags::empty().with_env();
        desc.backends = wgpu::Backends::from_env().unwrap_or_default();
        wgpu::Instance::new(desc)
    }

    async fn sorted_adapters(instance: &wgpu::Instance) -> Vec<wgpu::Adapter> {
        let backends = wgpu::Backends::from_env().unwrap_or_default();
        let mut adapters = instance.enumerate_adapters(backends).await;
        adapters.sort_by_key(|a| match a.get_info().device_type {
            wgpu::DeviceType::DiscreteGpu => 0,
            wgpu::DeviceType::IntegratedGpu => 1,
            wgpu::DeviceType::VirtualGpu => 2,
            wgpu::DeviceType::Cpu => 3,
            wgpu::DeviceType::Other => 4,
        });
        adapters
    }

    async fn new_async(index: Option<usize>) -> Result<Self, GpuError> {
        let instance = Self::instance();
        let adapter = match index {
            None => {
                instance
                    .request_adapter(&wgpu::RequestAdapterOptions {
                        power_preference: wgpu::PowerPreference::HighPerformance,
                        ..Default::default()
                    })
                    .await?
            }
            Some(index) => {
                let adapters = Self::sorted_adapters(&instance).await;
                let found = adapters.len();
                adapters.into_iter().nth(index).ok_or_else(|| {
                    GpuError::Unsupported(format!("adapter {index}: only {found} GPU adapters were found"))
                })?
            }
        };
        let wanted = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        // Timestamps are used on real GPUs. On CPU adapters they are not trusted: lavapipe
        // (Mesa 22.3) reported 0.05 ms for a gather that took 6.7 s of wall time. There each
        // stage is submitted and timed on its own. RELUME_TIMING=wall|gpu overrides.
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wanted)
            && match std::env::var("RELUME_TIMING").as_deref() {
                Ok("wall") => false,
                Ok("gpu") => true,
                _ => info.device_type != wgpu::DeviceType::Cpu,
            };
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("relume.device"),
                required_features: if timestamps { wanted } else { wgpu::Features::empty() },
                required_limits: adapter.limits(),
                ..Default::default()
            })
            .await?;
        let gather_lanes = gather_lanes_from_env()?;
        Ok(Self { device, queue, adapter_info: info, timestamps, gather_lanes })
    }

    /// VALs beyond which one invocation of the gather or the brute force on a CPU adapter would
    /// run past [`LLVMPIPE_LOOP_LIMIT`] (one loop iteration per VAL and two per tile) and
    /// silently drop the rest (with 125,676 VALs in one dispatch the brute force used exactly
    /// the first 63,551); both therefore split their VALs into ranges there
    /// ([`pass::Kernels::val_ranges`]). [`Gpu::is_cpu`] says whether it applies.
    pub const CPU_MAX_GATHERED_VALS: u32 = LLVMPIPE_LOOP_LIMIT / (shader::TILE_SIZE + 2) * shader::TILE_SIZE;

    /// Whether the adapter runs on the CPU (lavapipe / llvmpipe).
    pub fn is_cpu(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// Device memory live right now in buffers and textures, as wgpu's internal counters
    /// count it (the sizes of the driver allocations backing every buffer and texture this
    /// process holds on the device, alignment included; not pipelines or driver overhead).
    pub fn memory_in_use(&self) -> MemoryInUse {
        let hal = self.device.get_internal_counters().hal;
        let bytes = |c: isize| c.max(0) as u64;
        MemoryInUse { buffer_bytes: bytes(hal.buffer_memory.read()), texture_bytes: bytes(hal.texture_memory.read()) }
    }

    /// `"<name> (<backend>)"`, e.g. `"llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)"`.
    pub fn adapter_name(&self) -> String {
        format!("{} ({:?})", self.adapter_info.name, self.adapter_info.backend)
    }

    /// A storage buffer initialised from `data`, refusing sizes over the device limit.
    pub fn storage_buffer<T: Pod>(
        &self,
        label: &str,
        data: &[T],
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        self.check_size(label, bytes.len() as u64)?;
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (bytes.len() as u64).max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
            mapped_at_creation: false,
        });
        self.queue.write_buffer(&buffer, 0, bytes);
        Ok(buffer)
    }

    /// An uninitialised storage buffer of `count` elements of `T`.
    pub fn storage_buffer_sized<T: Pod>(&self, label: &str, count: usize) -> Result<wgpu::Buffer, GpuError> {
        let size = (count * std::mem::size_of::<T>()) as u64;
        self.check_size(label, size)?;
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }))
    }

    /// Whether a storage binding of `needed` bytes fits the device: else
    /// [`GpuError::TooLarge`] naming `what`.
    pub fn check_size(&self, what: &str, needed: u64) -> Result<(), GpuError> {
        let limits = self.device.limits();
        let limit = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        if needed > limit {
            return Err(GpuError::TooLarge { what: what.to_owned(), needed, limit });
        }
        Ok(())
    }

    /// Copy `count` elements of `T` out of `buffer` (which needs `COPY_SRC`) and wait for them.
    pub fn read_buffer<T: Pod>(&self, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>, GpuError> {
        let size = (count * std::mem::size_of::<T>()) as u64;
        if size == 0 {
            return Ok(Vec::new());
        }
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("relume.readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("relume.readback") });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        rx.recv().map_err(|e| GpuError::Map(e.to_string()))?.map_err(|e| GpuError::Map(e.to_string()))?;
        let data = slice.get_mapped_range().map_err(|e| GpuError::Map(e.to_string()))?;
        let out = bytemuck::cast_slice::<u8, T>(&data).to_vec();
        drop(data);
        staging.unmap();
        Ok(out)
    }

    /// Submit and wait until the device is idle.
    pub fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<(), GpuError> {
        self.queue.submit([encoder.finish()]);
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        Ok(())
    }

    /// Build shader modules, layouts or pipelines in `f` inside validation and internal error
    /// scopes, so that a shader or pipeline error comes back as [`GpuError::Pipeline`] for
    /// `label` instead of reaching wgpu's default handler, which panics. Internal errors are
    /// what a backend's shader translation raises (naga's GLSL writer refusing a construct on
    /// the GL backend, say).
    pub fn build_checked<R>(&self, label: &str, f: impl FnOnce() -> R) -> Result<R, GpuError> {
        let internal = self.device.push_error_scope(wgpu::ErrorFilter::Internal);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let r = f();
        let errors = [pollster::block_on(validation.pop()), pollster::block_on(internal.pop())];
        match errors.into_iter().flatten().next() {
            None => Ok(r),
            Some(e) => Err(GpuError::Pipeline {
                label: label.to_owned(),
                message: format!("{e} (on the {:?} backend)", self.adapter_info.backend),
            }),
        }
    }
}
