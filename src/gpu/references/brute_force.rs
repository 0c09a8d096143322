//! Brute-force reference (`brute_force.wgsl`, DESIGN.md §5). Rust twin:
//! `twin::shade_brute_force`. On CPU adapters the VALs go in ranges, one dispatch each,
//! each adding to the radiance of the ones before ([`Kernels::val_ranges`]).

use crate::gpu::pass::{Entry, Kernels, PassDesc, buffer, read, read_write, texture, view};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::{IMAGE_TILE, TILE_SIZE, VAL_TILES};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};

pub const WGSL: &str = include_str!("brute_force.wgsl");

/// The pass's own WGSL: the VAL tiles, then `brute_force.wgsl`.
pub fn body() -> String {
    format!("{VAL_TILES}\n{WGSL}")
}

/// One invocation per pixel; a workgroup (`IMAGE_TILE[0]` pixels wide, `TILE_SIZE` in all)
/// streams VALs through workgroup memory in tiles of `TILE_SIZE`.
pub const PASS: PassDesc = PassDesc {
    label: "brute_force",
    bindings: &[texture("visibility"), read_write("indirect"), read("vals"), read("val_count")],
    entries: &[Entry::first("main", 4), Entry::first("main_glossy", 4)],
    workgroup: [IMAGE_TILE[0], TILE_SIZE / IMAGE_TILE[0], 1],
    default_source: |textured| PASS.source(&body(), textured),
};

pub struct BruteForce {
    kernels: Kernels,
}

impl BruteForce {
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool) -> Result<Self, GpuError> {
        let source = PASS.source(&body(), scene.textured());
        let entry = PASS.lobe_entry(glossy);
        let kernels = Kernels::val_ranges(gpu, scene, &PASS, source, entry, PASS.workgroup, TILE_SIZE)?;
        Ok(Self { kernels })
    }

    /// Cover frames of up to `max_vals` VALs (see [`Kernels::fit`]).
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        self.kernels.fit(gpu, scene, max_vals)
    }
}

impl Technique for BruteForce {
    fn stages(&self) -> Vec<&'static str> {
        vec![PASS.label]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let camera = &frame.camera;
        let resources = [
            view("visibility", &camera.view.view),
            buffer("indirect", &camera.indirect),
            buffer("vals", &frame.vals.buffer),
            buffer("val_count", &frame.vals.count),
        ];
        let pixels = [camera.view.width, camera.view.height, 1];
        rec.stage(PASS.label, |e, s| self.kernels.run(gpu, e, frame.scene, &resources, pixels, s))
    }
}
