//! How much of the disc occluders' work the `occlusion` pass's groups skip
//! (docs/techniques/disc-occlusion.md): one sparse frame of the scene, its gathered light
//! spheres read back, the sparse points in the pass's Morton order, cut into groups of
//! `group` discs, and for every workgroup of `receivers` receivers in the same order, the groups
//! that at least one of its receivers cannot rule out (`disks::twin::group_may_occlude`).
//! Prints the fraction of (workgroup, group) visits kept, which is the fraction of the
//! lanes x discs the pass still walks when every lane of a workgroup walks what any lane needs,
//! and the fraction of (receiver, group) pairs kept.
//!
//! ```sh
//! cargo run --release --example disc_cull_estimate -- fixtures/scenes/sponza_bunny.json 64 16
//! ```

use glam::Vec3;
use relume::gpu::Gpu;
use relume::gpu::visibility::disks::twin::{
    Disc, disc_groups, group_may_occlude, light_sphere, morton_order, projected_sphere,
};
use relume::renderer::{Method, Renderer};
use relume::scene::Scene;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: disc_cull_estimate <scene.json> [receivers per workgroup] [discs per group]";
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!(usage))?;
    let receivers: usize = args.get(2).map_or(Ok(64), |s| s.parse())?;
    let group: usize = args.get(3).map_or(Ok(16), |s| s.parse())?;
    anyhow::ensure!(receivers > 0 && group > 0, "{usage}: both at least 1");
    let scene = Scene::load(std::path::Path::new(path))?;
    let gpu = Gpu::new()?;
    let mut renderer = Renderer::new(&gpu, &scene)?;
    renderer.render(&gpu, Method::Sparse, 64, 64)?;
    let gathered = renderer.read_sparse_intermediates(&gpu)?.gathered_diffuse;
    let points = &renderer.scene.flat.sparse_points;
    let discs: Vec<Disc> = points
        .iter()
        .map(|p| Disc { position: p.position.into(), normal: p.normal.into(), radius: p.occluder_radius })
        .collect();
    let order = morton_order(&discs.iter().map(|d| d.position).collect::<Vec<Vec3>>());
    let groups = disc_groups(&discs, &order, group);
    let (mut visits, mut kept_visits, mut kept_pairs) = (0u64, 0u64, 0u64);
    for workgroup in order.chunks(receivers) {
        let seen: Vec<_> = workgroup
            .iter()
            .filter_map(|&i| {
                let (d, g) = (&discs[i as usize], &gathered[i as usize]);
                let sphere = light_sphere(g.position.into(), g.second_moment.into());
                projected_sphere(d.position, d.normal, &sphere).map(|(t, b, s)| (d.position, d.normal, t, b, s))
            })
            .collect();
        for g in &groups {
            visits += 1;
            let needing = seen.iter().filter(|(x, n, t, b, s)| group_may_occlude(*x, *n, *t, *b, s, g)).count();
            kept_pairs += needing as u64;
            kept_visits += u64::from(needing > 0);
        }
    }
    let pairs = points.len() as u64 * groups.len() as u64;
    println!(
        "{path}: {} sparse points, {} groups of {group}, workgroups of {receivers}: visits kept {kept_visits} of \
         {visits} ({:.3}), receiver-group pairs kept {kept_pairs} of {pairs} ({:.3})",
        points.len(),
        groups.len(),
        kept_visits as f64 / visits as f64,
        kept_pairs as f64 / pairs as f64,
    );
    Ok(())
}
