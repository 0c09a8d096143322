//! The clusters' visibility by shadow rays (`settings.tuning.clusters.shadow_maps: "rays"`): no
//! maps; each (sparse point, cluster) casts `rays` shadow rays through the scene's BVH to that
//! many of the cluster's VALs (`ray_visibility.wgsl`), drawn from per-cluster member lists that a
//! counting sort makes every frame after k-means (`ray_members.wgsl`). Exact visibility for the
//! VALs it draws, so what is left of the shadow maps' error is the draw's noise and the one
//! visibility per cluster. Rust twins: [`twin::member_lists`], [`twin::ray_visibility`].
//!
//! The BVH is built from the meshes as placed when the mode is built; the renderer rebuilds the
//! mode when the meshes move (`Renderer::place_meshes`).

use super::twin;
use crate::gpu::pass::{Entry, Kernel, PassDesc, Res, buffer, module_from_source, read, read_write};
use crate::gpu::references::exact::EXACT_LOOP_BUDGET;
use crate::gpu::references::rounds::{BVH_WGSL, bvh_buffers};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::{WORKGROUP_SIZE, Wgsl};
use crate::gpu::technique::Frame;
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};
use crate::scene::ClusterSettings;

const MEMBERS_WGSL: &str = include_str!("ray_members.wgsl");
const VISIBILITY_WGSL: &str = include_str!("ray_visibility.wgsl");

/// Loop iterations (draws and BVH steps of all its rays) one entry runs: under llvmpipe's loop
/// limit, as the exact reference's per round. A ray it cuts off does not count.
pub const RAY_LOOP_BUDGET: u32 = EXACT_LOOP_BUDGET;

/// The member lists' stage.
pub const MEMBERS_STAGE: &str = "cluster_ray_members";

/// The counting sort of the VALs by cluster: three entry points over one set of bindings.
pub const MEMBERS: PassDesc = PassDesc {
    label: MEMBERS_STAGE,
    bindings: &[read("val_count"), read("group_of_val"), read_write("ray_members")],
    entries: &[
        Entry::first("members_count", 3),
        Entry { name: "members_scan", bindings: 3, except: &["val_count", "group_of_val"] },
        Entry::first("members_scatter", 3),
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| MEMBERS.source(&members_body(&super::default_header()), textured),
};

/// Per (sparse point, cluster) visibility by shadow rays.
pub const VISIBILITY: PassDesc = PassDesc {
    label: "cluster_ray_visibility",
    bindings: &[
        read("sparse_points"),
        read("vals"),
        read("ray_members"),
        read_write("group_visibility"),
        read("bvh_nodes"),
        read("bvh_triangles"),
    ],
    entries: &[Entry::first("main", 6)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        VISIBILITY.source(&visibility_body(&super::default_header(), &ClusterSettings::default()), textured)
    },
};

fn members_body(head: &str) -> String {
    Wgsl::new().include(head).include(MEMBERS_WGSL).finish()
}

/// The visibility pass's WGSL after the mode's constants `head`.
pub fn visibility_body(head: &str, settings: &ClusterSettings) -> String {
    Wgsl::new()
        .include(head)
        .u32("CLUSTER_RAYS", settings.rays)
        .u32("RAY_LOOP_BUDGET", RAY_LOOP_BUDGET)
        .include(BVH_WGSL)
        .include(VISIBILITY_WGSL)
        .finish()
}

/// The member lists and the BVH the rays traverse.
pub(super) struct Rays {
    count: Kernel,
    scan: Kernel,
    scatter: Kernel,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    /// `ray_members.wgsl`'s cursors, starts and members, for [`Rays::capacity`] VALs.
    members: wgpu::Buffer,
    capacity: u32,
    clusters: u32,
}

impl Rays {
    pub(super) fn new(gpu: &Gpu, scene: &GpuScene, settings: &ClusterSettings, head: &str) -> Result<Self, GpuError> {
        let module = module_from_source(gpu, MEMBERS.label, MEMBERS.source(&members_body(head), scene.textured()))?;
        let kernel =
            |name: &str| Kernel::build(gpu, scene, &MEMBERS, &module, MEMBERS.entry(name), &[], MEMBERS.workgroup);
        let (nodes, order) = bvh_buffers(gpu, scene, VISIBILITY.label)?;
        let clusters = settings.count;
        Ok(Self {
            count: kernel("members_count")?,
            scan: kernel("members_scan")?,
            scatter: kernel("members_scatter")?,
            nodes,
            order,
            members: Self::members_buffer(gpu, clusters, 1)?,
            capacity: 1,
            clusters,
        })
    }

    fn members_buffer(gpu: &Gpu, clusters: u32, vals: u32) -> Result<wgpu::Buffer, GpuError> {
        let words = 2 * clusters as usize + 1 + vals as usize;
        gpu.storage_buffer_sized::<u32>(&format!("{MEMBERS_STAGE}.ray_members"), words)
    }

    /// Cover frames of up to `max_vals` VALs.
    pub(super) fn fit(&mut self, gpu: &Gpu, max_vals: u32) -> Result<(), GpuError> {
        if max_vals > self.capacity {
            self.members = Self::members_buffer(gpu, self.clusters, max_vals)?;
            self.capacity = max_vals;
        }
        Ok(())
    }

    /// Record the member lists of the frame's VALs from `group_of_val` (k-means' assignment).
    pub(super) fn record(
        &self,
        gpu: &Gpu,
        frame: &Frame<'_>,
        group_of_val: &wgpu::Buffer,
        rec: &mut Recorder<'_>,
    ) -> Result<(), GpuError> {
        let resources = || {
            [
                buffer("val_count", &frame.vals.count),
                buffer("group_of_val", group_of_val),
                buffer("ray_members", &self.members),
            ]
        };
        let count = self.count.bind(gpu, &resources());
        let scan = self.scan.bind(gpu, &[buffer("ray_members", &self.members)]);
        let scatter = self.scatter.bind(gpu, &resources());
        let (vals, cursors) = (self.capacity, u64::from(self.clusters) * 4);
        rec.stage(MEMBERS_STAGE, |e, s| {
            e.clear_buffer(&self.members, 0, Some(cursors));
            self.count.dispatch(e, &count, frame.scene, [vals, 1, 1], s.as_ref().and_then(|s| s.compute_part(0, 3)));
            self.scan.dispatch(e, &scan, frame.scene, [1, 1, 1], s.as_ref().and_then(|s| s.compute_part(1, 3)));
            self.scatter.dispatch(e, &scatter, frame.scene, [vals, 1, 1], s.as_ref().and_then(|s| s.compute_part(2, 3)));
        })
    }

    /// The visibility pass's resources after the receivers and before the table.
    pub(super) fn resources<'a>(&'a self, frame: &Frame<'a>) -> [Res<'a>; 2] {
        [buffer("vals", &frame.vals.buffer), buffer("ray_members", &self.members)]
    }

    /// The BVH's resources, after the table.
    pub(super) fn bvh(&self) -> [Res<'_>; 2] {
        [buffer("bvh_nodes", &self.nodes), buffer("bvh_triangles", &self.order)]
    }

    /// The last frame's member lists (tests and tools).
    pub(super) fn read(&self, gpu: &Gpu, vals: usize) -> Result<twin::MemberLists, GpuError> {
        let m = self.clusters as usize;
        let words: Vec<u32> = gpu.read_buffer(&self.members, 2 * m + 1 + vals.min(self.capacity as usize))?;
        let starts = words[m..=2 * m].to_vec();
        let members = words[2 * m + 1..].iter().take(starts[m] as usize).copied().collect();
        Ok(twin::MemberLists { starts, members })
    }
}
