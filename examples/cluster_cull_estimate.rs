//! What a hemisphere cull could save the clusters mode's shadow maps (README "Clustered
//! visibility", its cost target): one sparse frame of the scene with `visibility:
//! "clusters"` at its cluster settings, its clusters read back, and for every cluster the
//! triangles whose box reaches the front of the cluster's plane (each map sees only that
//! hemisphere), counted in the lights' RSM cull's chunks (`raster::cull`) and per triangle,
//! against every triangle into every map as now; with the frame's `cluster_shadow_maps` and
//! `gather` times. A box counts as behind when its farthest corner along the normal lies behind
//! the plane by more than 3 x `SHADOW_RASTER_SLACK` of its diagonal (the raster's barycentric
//! slack widens a triangle by about that much), so the estimate keeps what the maps need.
//!
//! ```sh
//! cargo run --release --example cluster_cull_estimate -- fixtures/scenes/cornell_bunny.json 128 128
//! ```

use glam::Vec3;
use relume::gpu::Gpu;
use relume::gpu::raster::cull::TriangleChunks;
use relume::gpu::visibility::clusters::{Clusters, twin};
use relume::renderer::{Method, Renderer};
use relume::scene::{Occlusion, Scene};

/// Whether the box `[lo, hi]` may reach the front of the plane through `c` with normal `n`.
fn in_front(lo: Vec3, hi: Vec3, c: Vec3, n: Vec3) -> bool {
    let far = Vec3::select(n.cmpge(Vec3::ZERO), hi, lo);
    (far - c).dot(n) >= -3.0 * twin::SHADOW_RASTER_SLACK * (hi - lo).length()
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path =
        args.get(1).ok_or_else(|| anyhow::anyhow!("usage: cluster_cull_estimate <scene.json> [width] [height]"))?;
    let width: u32 = args.get(2).map_or(Ok(128), |s| s.parse())?;
    let height: u32 = args.get(3).map_or(Ok(128), |s| s.parse())?;
    anyhow::ensure!((1..=1024).contains(&width) && (1..=1024).contains(&height), "sides: 1..=1024");
    let mut scene = Scene::load(std::path::Path::new(path))?;
    scene.settings.visibility.mode = Occlusion::Clusters;
    let gpu = Gpu::new()?;
    let mut renderer = Renderer::new(&gpu, &scene)?;
    let frame = renderer.render(&gpu, Method::Sparse, width, height)?;
    let group = renderer.group_visibility().ok_or_else(|| anyhow::anyhow!("no group visibility ran"))?;
    let clusters = group.as_any().downcast_ref::<Clusters>().ok_or_else(|| anyhow::anyhow!("not the clusters mode"))?;
    let r = clusters.read(&gpu, frame.val_count as usize, renderer.scene.flat.sparse_points.len())?;
    let flat = &renderer.scene.flat;
    let triangles = flat.triangle_count() as u64;
    let maps = r.clusters.iter().filter(|c| c.count > 0.0).count() as u64;
    println!("{path}, {width}x{height}: {} clusters ({maps} not empty), {triangles} triangles", r.clusters.len());
    for chunk in [1u32, relume::gpu::raster::cull::CHUNK_TRIANGLES] {
        let chunks = TriangleChunks::with_chunk(flat, chunk);
        let mut kept = 0u64;
        for c in r.clusters.iter().filter(|c| c.count > 0.0) {
            for (i, &(lo, hi)) in chunks.chunks.iter().enumerate() {
                if in_front(lo, hi, c.position, c.normal) {
                    let start = i as u64 * chunk as u64;
                    kept += (start + chunk as u64).min(triangles) - start;
                }
            }
        }
        println!(
            "chunks of {chunk}: {kept} of {} triangle draws kept ({:.3})",
            maps * triangles,
            kept as f64 / (maps * triangles) as f64
        );
    }
    let ms = |name: &str| frame.timings.stages.iter().find(|(n, _)| n == name).map_or(0.0, |(_, ms)| *ms);
    println!(
        "cluster_shadow_maps {:.0} ms, cluster_visibility {:.0} ms, clustering {:.0} ms, gather {:.0} ms",
        ms("cluster_shadow_maps"),
        ms("cluster_visibility"),
        ms("clustering"),
        ms(relume::renderer::stage::GATHER)
    );
    Ok(())
}
