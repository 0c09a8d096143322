//! How many VALs the near-field pass (`gpu::sparse::near_field`) visits per pixel against those
//! within its radius: one sparse frame of the scene at 256x256, its VALs read back and sorted
//! into the pass's grid (`twin::near_field::ValGrid`, cells twice the radius wide, the 2x2x2
//! around each receiver), and at every covered pixel's surface point the grid's VALs counted,
//! and those within the radius. The scene's `settings.tuning.sparse.near_field` must be set
//! (or its level's).
//!   cargo run --release --example nf_visits -- <scene.json>
use relume::renderer::{Method, Renderer};
use relume::twin::near_field::{ValGrid, bucket_count};
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let scene = relume::scene::Scene::load(std::path::Path::new(&path)).unwrap();
    let gpu = relume::gpu::Gpu::new().unwrap();
    let radius = scene.settings.sparse.near_field * scene.sparse_spacing();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.render(&gpu, Method::Sparse, 256, 256).unwrap();
    let vals = renderer.read_vals(&gpu).unwrap();
    let grid = ValGrid::build(&vals, radius, bucket_count(vals.len() as u32), 1);
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let (flat, mut visited, mut within, mut weighted, mut pixels) =
        (&renderer.scene.flat, 0usize, 0usize, 0usize, 0usize);
    for h in hits.iter().flatten() {
        let (p, _, _) = flat.surface_at(h.triangle, h.barycentrics);
        pixels += 1;
        for v in grid.near_vals(p, 0) {
            visited += 1;
            let d = v.position.distance(p);
            within += usize::from(d < radius);
            weighted += usize::from(relume::twin::near_field_weight(d, radius) > 0.0);
        }
    }
    let f = |n: usize| n as f64 / pixels as f64;
    println!(
        "{path}: {} VALs, radius {radius:.3} m, {pixels} pixels; per pixel: visited {:.1}, within radius {:.1}, weight > 0 {:.1}; visited / within {:.2}",
        vals.len(),
        f(visited),
        f(within),
        f(weighted),
        visited as f64 / within.max(1) as f64
    );
}
