//! The near field's rest (the VALs past the close radius of the interleaved form,
//! `twin::near_field::close_radius` at N = 4) from VALs merged in small cells, against the same
//! rest from every VAL: how far merging would move the near field, and how many VALs a pixel
//! would visit instead. One sparse frame of the scene at 256 pixels wide (its own aspect), its
//! VALs read back; at every second covered pixel on each axis (the receiver's surface point as
//! its near-field centre) the terms of `twin::near_field::terms_weighted` over the grid's VALs
//! (`ValGrid`, cells twice the radius), each weighted by its rest share; merged, the VALs of a
//! cell of side `radius / k` become one (flux summed; position and normal weighted by the flux's
//! sum over its channels; area summed), weighted by the rest share at its own position; then
//! the same per cell and per face of the cube the VAL's normal points through most; last, cells
//! sized with the distance ([`Tree::cut`]: cells from a radius over 4 to over 32, a cell's merged
//! VAL taken where the cell's side is at most 1/alpha of its distance, for alpha 2, 4, 8). The
//! error is the RMSE of the irradiance's difference over the pixels, relative to the RMS of the
//! whole near field (close share and rest) there. `settings.tuning.sparse.near_field` is set to
//! 4 where the scene leaves it 0.
//!   cargo run --release --example nf_merge -- <scene.json> [k ...]   (default k: 4 8 16)
use std::collections::HashMap;

use glam::{IVec3, Vec3};
use relume::renderer::{Method, Renderer};
use relume::twin::exact_cpu::Receiver;
use relume::twin::near_field::{ValGrid, bucket_count, cell_of, close_radius, terms_weighted};
use relume::twin::near_field_weight;
use relume::val::Val;

/// The face of the cube a unit normal points through most (0-5): VALs merged by cell and face
/// keep walls apart from floors.
fn face(n: Vec3) -> u8 {
    let a = n.abs();
    let (axis, c) = if a.x >= a.y && a.x >= a.z {
        (0, n.x)
    } else if a.y >= a.z {
        (1, n.y)
    } else {
        (2, n.z)
    };
    2 * axis + u8::from(c < 0.0)
}

/// `vals` as one VAL: flux and area summed, position and normal weighted by the flux's sum over
/// its channels.
fn merge<'a>(vals: impl IntoIterator<Item = &'a Val>) -> Val {
    let (mut flux, mut p, mut n, mut area, mut total) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, 0.0, 0.0);
    for v in vals {
        let w = v.flux.x + v.flux.y + v.flux.z + 1e-20;
        flux += v.flux;
        p += w * v.position;
        n += w * v.normal;
        area += v.area;
        total += w;
    }
    Val { position: p / total, normal: n.try_normalize().unwrap_or(Vec3::Y), area, flux }
}

/// `vals` merged per cell of side `side`, and per normal's [`face`] too when `by_face`.
fn merged(vals: &[Val], side: f32, by_face: bool) -> Vec<Val> {
    let mut cells: HashMap<(IVec3, u8), Vec<&Val>> = HashMap::new();
    for v in vals {
        let key = (cell_of(v.position, side), if by_face { face(v.normal) } else { 0 });
        cells.entry(key).or_default().push(v);
    }
    cells.into_values().map(merge).collect()
}

/// VALs merged at every level of cells of side `sides[l]` (each half the one before), each
/// level's cells split into the next's, the last into the VALs themselves.
struct Tree {
    sides: Vec<f32>,
    /// Per level: per cell, its merged VAL and its children (cells of the next level, or VAL
    /// indices below the last).
    levels: Vec<HashMap<IVec3, (Val, Vec<IVec3>)>>,
    leaves: HashMap<IVec3, Vec<usize>>,
}

impl Tree {
    fn build(vals: &[Val], sides: Vec<f32>) -> Self {
        let mut levels: Vec<HashMap<IVec3, (Val, Vec<IVec3>)>> = Vec::new();
        for (l, &side) in sides.iter().enumerate() {
            let mut cells: HashMap<IVec3, Vec<usize>> = HashMap::new();
            for (i, v) in vals.iter().enumerate() {
                cells.entry(cell_of(v.position, side)).or_default().push(i);
            }
            let level = cells
                .into_iter()
                .map(|(key, members)| {
                    let merged = merge(members.iter().map(|&i| &vals[i]));
                    let mut children: Vec<IVec3> = match sides.get(l + 1) {
                        Some(&next) => members.iter().map(|&i| cell_of(vals[i].position, next)).collect(),
                        None => Vec::new(),
                    };
                    children.sort_by_key(|c| (c.x, c.y, c.z));
                    children.dedup();
                    (key, (merged, children))
                })
                .collect();
            levels.push(level);
        }
        let mut leaves: HashMap<IVec3, Vec<usize>> = HashMap::new();
        let last = *sides.last().expect("a level");
        for (i, v) in vals.iter().enumerate() {
            leaves.entry(cell_of(v.position, last)).or_default().push(i);
        }
        Self { sides, levels, leaves }
    }

    /// The VALs (merged or not) a receiver at `p` takes: a cell's merged VAL where it lies at
    /// least `alpha` of its cell's sides away, else its children's.
    fn cut<'a>(&'a self, vals: &'a [Val], p: Vec3, alpha: f32, out: &mut Vec<&'a Val>) {
        let mut stack: Vec<(usize, IVec3)> = self.levels[0].keys().map(|k| (0, *k)).collect();
        while let Some((l, key)) = stack.pop() {
            let (merged, children) = &self.levels[l][&key];
            if merged.position.distance(p) >= alpha * self.sides[l] {
                out.push(merged);
            } else if l + 1 < self.levels.len() {
                stack.extend(children.iter().map(|c| (l + 1, *c)));
            } else {
                out.extend(self.leaves[&key].iter().map(|&i| &vals[i]));
            }
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("a scene file");
    let ks: Vec<f32> = args.map(|a| a.parse().expect("k: a number")).collect();
    let ks = if ks.is_empty() { vec![4.0, 8.0, 16.0] } else { ks };
    let mut scene = relume::scene::Scene::load(std::path::Path::new(&path)).unwrap();
    if scene.settings.sparse.near_field <= 0.0 {
        scene.settings.sparse.near_field = 4.0;
    }
    let gpu = relume::gpu::Gpu::new().unwrap();
    let radius = scene.settings.sparse.near_field * scene.sparse_spacing();
    let close = close_radius(radius, 4);
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let (w, h) = (256, (256 * scene.camera.height / scene.camera.width).max(1));
    renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let vals = renderer.read_vals(&gpu).unwrap();
    let eye = renderer.view().eye();
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let flat = &renderer.scene.flat;
    let receivers: Vec<_> = hits
        .iter()
        .enumerate()
        .filter(|(i, _)| (i % w as usize).is_multiple_of(2) && (i / w as usize).is_multiple_of(2))
        .filter_map(|(_, h)| h.map(|h| flat.receiver_at(h.triangle, h.barycentrics, eye)))
        .collect();
    let rest = |d: f32| near_field_weight(d, radius) - near_field_weight(d, close);
    let grid = ValGrid::build(&vals, radius, bucket_count(vals.len() as u32), 1);
    let luminance = |e: Vec3| e.x + e.y + e.z;
    // The irradiance at `r` of `near`, each VAL weighted by `share` of its distance, and how many
    // of them have a share.
    let terms_at = |r: &Receiver, near: &[Val], share: &dyn Fn(f32) -> f32| {
        let weighted = near.iter().map(|v| (v, share(v.position.distance(r.position))));
        let counted = weighted.clone().filter(|(_, w)| *w > 0.0).count();
        let t = terms_weighted((r.position, r.normal, r.geometric), r.surface.exponent, eye, weighted, false);
        (t.irradiance, counted)
    };
    // Every VAL: the close share, the rest, and how many VALs the rest takes (share > 0).
    let (mut whole2, mut within) = (0.0f64, 0usize);
    let exact: Vec<Vec3> = receivers
        .iter()
        .map(|r| {
            let near: Vec<Val> = grid.near_vals(r.position, 0).copied().collect();
            let (close_irradiance, _) = terms_at(r, &near, &|d| near_field_weight(d, close));
            let (rest_irradiance, counted) = terms_at(r, &near, &rest);
            within += counted;
            whole2 += f64::from(luminance(close_irradiance + rest_irradiance)).powi(2);
            rest_irradiance
        })
        .collect();
    let n = receivers.len().max(1) as f64;
    println!(
        "{path}: {} VALs, radius {radius:.3} m, close radius {close:.3} m, {} receivers; every VAL: {:.1} in the rest \
         per receiver",
        vals.len(),
        receivers.len(),
        within as f64 / n
    );
    // With the VALs `near_of` gives at a receiver's position instead: how far the near field
    // moves (RMSE over the RMS of the whole near field) and the rest's VALs per receiver.
    let moved = |near_of: &dyn Fn(Vec3) -> Vec<Val>| {
        let (mut err2, mut used) = (0.0f64, 0usize);
        for (r, e) in receivers.iter().zip(&exact) {
            let (irradiance, counted) = terms_at(r, &near_of(r.position), &rest);
            used += counted;
            err2 += f64::from(luminance(irradiance - *e)).powi(2);
        }
        ((err2 / whole2.max(1e-30)).sqrt(), used as f64 / n)
    };
    for (k, by_face) in ks.iter().flat_map(|&k| [(k, false), (k, true)]) {
        let merged = merged(&vals, radius / k, by_face);
        let grid = ValGrid::build(&merged, radius, bucket_count(merged.len() as u32), 1);
        let (error, used) = moved(&|p| grid.near_vals(p, 0).copied().collect());
        println!(
            "  merged in cells of radius/{k}{}: {} VALs; {used:.1} in the rest per receiver; near field's irradiance \
             moved by {error:.4} (RMSE over the RMS of the whole near field)",
            if by_face { " and by the normal's face" } else { "" },
            merged.len(),
        );
    }
    // Cells sized with the distance: sides radius/4 to radius/32, a merged VAL taken where its
    // cell is at most 1/alpha of its distance.
    let tree = Tree::build(&vals, [4.0, 8.0, 16.0, 32.0].map(|k| radius / k).to_vec());
    for alpha in [2.0, 4.0, 8.0] {
        let (error, used) = moved(&|p| {
            let mut near = Vec::new();
            tree.cut(&vals, p, alpha, &mut near);
            near.into_iter().copied().collect()
        });
        println!(
            "  merged in cells sized with the distance (radius/4 to radius/32, a cell at most 1/{alpha} of its \
             distance): {used:.1} in the rest per receiver; near field's irradiance moved by {error:.4}"
        );
    }
}
