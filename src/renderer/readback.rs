//! The renderer's readbacks for the CPU twins, tests and diagnostics: the last frame's VALs,
//! views and the sparse method's intermediate buffers.

use super::Renderer;
use crate::gpu::lights::bounce::SecondBounce;
use crate::gpu::raster::VisibilityTarget;
use crate::gpu::raw::{RawGathered, RawPointLight, RawVal};
use crate::gpu::sparse::SparseMethod;
use crate::gpu::technique::{CameraTarget, Technique};
use crate::gpu::{Gpu, GpuError, Lobes};
use glam::Vec3;

/// An image's RGBA pixels, row-major.
type Pixels = Vec<[f32; 4]>;

/// A frame's indirect and direct images (RGBA per pixel, alpha the coverage) from `target`:
/// those the frame wrote (`indirect`, `direct`), the other one coverage alone; coverage from the
/// visibility buffer when it wrote neither.
pub(super) fn camera_images(
    gpu: &Gpu,
    target: &CameraTarget,
    indirect: bool,
    direct: bool,
) -> Result<(Pixels, Pixels), GpuError> {
    let pixels = (target.view.width * target.view.height) as usize;
    let coverage_only = |image: &[[f32; 4]]| image.iter().map(|p| [0.0, 0.0, 0.0, p[3]]).collect::<Vec<_>>();
    Ok(match (indirect, direct) {
        (true, true) => {
            (gpu.read_buffer::<[f32; 4]>(&target.indirect, pixels)?, gpu.read_buffer(&target.direct, pixels)?)
        }
        (true, false) => {
            let indirect = gpu.read_buffer::<[f32; 4]>(&target.indirect, pixels)?;
            let direct = coverage_only(&indirect);
            (indirect, direct)
        }
        (false, true) => {
            let direct = gpu.read_buffer::<[f32; 4]>(&target.direct, pixels)?;
            (coverage_only(&direct), direct)
        }
        (false, false) => {
            // Neither wrote the camera's images: coverage from its visibility buffer.
            let coverage: Pixels =
                target.view.read(gpu)?.iter().map(|h| [0.0, 0.0, 0.0, if h.is_some() { 1.0 } else { 0.0 }]).collect();
            (coverage.clone(), coverage)
        }
    })
}

impl Renderer {
    /// The camera's visibility buffer of the last frame.
    pub fn camera_view(&self) -> Option<&VisibilityTarget> {
        self.target.as_ref().map(|t| &t.view)
    }

    /// The live VALs of the last frame (for the CPU twins and diagnostics).
    pub fn read_vals(&self, gpu: &Gpu) -> Result<Vec<crate::twin::Val>, GpuError> {
        let n = self.live_val_count(gpu)? as usize;
        Ok(gpu.read_buffer::<RawVal>(&self.vals.buffer, n)?.iter().map(Into::into).collect())
    }

    /// The second bounce (`settings.bounces: 2`), when the scene has one.
    pub fn second_bounce(&self) -> Option<&SecondBounce> {
        self.bounce.as_ref()
    }

    /// The second bounce's stages (none with one bounce).
    pub fn bounce_stages(&self) -> Vec<&'static str> {
        self.bounce.as_ref().map_or_else(Vec::new, |b| b.stages())
    }

    /// The stages of the sparse method's visibility mode, as last built (none when off).
    pub fn visibility_stages(&self) -> Vec<&'static str> {
        self.sparse().and_then(|s| s.visibility.as_ref()).map_or_else(Vec::new, |m| m.stages())
    }

    /// The sparse method's group visibility mode, once a sparse frame with one was rendered.
    pub fn group_visibility(&self) -> Option<&dyn crate::gpu::visibility::GroupVisibility> {
        match &self.sparse()?.visibility {
            Some(crate::gpu::visibility::Mode::Groups(g)) => Some(g.as_ref()),
            _ => None,
        }
    }

    /// `brute_force_ism`'s or `brute_force_clusters`' groups and maps, once a frame of either
    /// method was rendered (the last one's).
    pub fn brute_force_groups(&self) -> Option<&crate::gpu::visibility::clusters::Clusters> {
        self.indirect.brute_force_grouped.as_ref()?.technique.groups()
    }

    /// The sparse technique, once a sparse frame was rendered.
    pub(super) fn sparse(&self) -> Option<&SparseMethod> {
        self.indirect.sparse.as_ref().map(|b| &b.technique)
    }

    /// Diffuse irradiance (W/m²) the last sparse frame gathered at each sparse point (after
    /// occlusion); empty before the first sparse frame.
    pub fn read_gathered_irradiance(&self, gpu: &Gpu) -> Result<Vec<Vec3>, GpuError> {
        let Some(p) = self.sparse() else {
            return Ok(Vec::new());
        };
        let gathered = gpu.read_buffer::<RawGathered>(&p.gathered.diffuse, self.scene.flat.sparse_points.len())?;
        Ok(gathered.iter().map(|g| Vec3::from(g.irradiance)).collect())
    }

    /// The last sparse frame's intermediate buffers: (gathered, sparse lights, vertex lights),
    /// each per lobe (glossy empty when the scene has none).
    pub fn read_sparse_intermediates(&self, gpu: &Gpu) -> Result<SparseIntermediates, GpuError> {
        let Some(p) = self.sparse() else {
            return Ok(SparseIntermediates::default());
        };
        let n = self.scene.flat.sparse_points.len();
        let v = self.scene.flat.vertices.len();
        let (gathered_diffuse, gathered_glossy) = read_lobes::<RawGathered>(gpu, &p.gathered, n)?;
        let (sparse_diffuse, sparse_glossy) = read_lobes::<RawPointLight>(gpu, &p.sparse_lights, n)?;
        let (vertex_diffuse, vertex_glossy) = read_lobes::<RawPointLight>(gpu, &p.vertex_lights, v)?;
        let vertex_glossy_radiance = match &p.vertex_glossy_radiance {
            Some(b) => gpu.read_buffer::<[f32; 4]>(b, v)?,
            None => Vec::new(),
        };
        let c = self.scene.flat.candidates as usize;
        let (adaptive_scores, adaptive_chosen) = match &p.adaptive {
            Some((a, _)) => (gpu.read_buffer::<f32>(&a.scores, c)?, gpu.read_buffer::<u32>(&a.chosen, c)?),
            None => (Vec::new(), Vec::new()),
        };
        Ok(SparseIntermediates {
            gathered_diffuse,
            gathered_glossy,
            sparse_diffuse,
            sparse_glossy,
            vertex_diffuse,
            vertex_glossy,
            vertex_glossy_radiance,
            adaptive_scores,
            adaptive_chosen,
        })
    }
}

/// Both lobes of `l` (the glossy one empty when absent).
fn read_lobes<T: bytemuck::Pod>(gpu: &Gpu, l: &Lobes, count: usize) -> Result<(Vec<T>, Vec<T>), GpuError> {
    let glossy = match &l.glossy {
        Some(b) => gpu.read_buffer::<T>(b, count)?,
        None => Vec::new(),
    };
    Ok((gpu.read_buffer::<T>(&l.diffuse, count)?, glossy))
}

/// GPU intermediates of the sparse pipeline, read back.
#[derive(Default)]
pub struct SparseIntermediates {
    pub gathered_diffuse: Vec<RawGathered>,
    pub gathered_glossy: Vec<RawGathered>,
    pub sparse_diffuse: Vec<RawPointLight>,
    pub sparse_glossy: Vec<RawPointLight>,
    pub vertex_diffuse: Vec<RawPointLight>,
    /// Empty with `glossy_interpolation: "radiance"`.
    pub vertex_glossy: Vec<RawPointLight>,
    /// Per vertex, the interpolated glossy radiance factor (xyz; `w` 0): with
    /// `glossy_interpolation: "radiance"` only.
    pub vertex_glossy_radiance: Vec<[f32; 4]>,
    /// Per adaptive candidate (`settings.sparse.adaptive`), this frame's score and whether it
    /// was chosen (1); empty without candidates.
    pub adaptive_scores: Vec<f32>,
    pub adaptive_chosen: Vec<u32>,
}
