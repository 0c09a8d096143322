//! Running the bench: its options, the jobs (the scene file, or the built scenes of
//! `--table1`) and each configuration's renders and measurements.

use super::compare::{self};
use super::{BenchError, equal_error, flag_error, fma, table1, temporal};
use crate::gpu::Gpu;
use crate::gpu::timing::TimingSource;
use crate::gpu::visibility::VisibilitySettings;
use crate::renderer::{Method, Rendered, Renderer, stage};
use crate::scene::{
    GlossyInterpolation, InterpolationKernel, IsmSettings, LightBound, Occlusion, Scene, SceneDescription,
};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::config::{Config, describe};
use super::plot;
use super::results::{BenchResults, BruteForceIsmResult, ConfigResult, GPU_MEMORY_NOTE, write_file, write_results};
use super::sweep::Sweep;

/// What `relume bench` was asked to do.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub scene: PathBuf,
    pub sweep: Sweep,
    pub grid: bool,
    /// A tiny sweep at a tiny resolution that runs in seconds (CI's smoke test).
    pub quick: bool,
    /// Also compare against exact visibility, computed as these options say (checked with
    /// [`compare::ExactOptions::check`]); on the device `compare` would choose.
    pub exact: Option<compare::ExactOptions>,
    /// With `exact`: the converging estimator's sample counts for the speed at equal error
    /// ([`equal_error`]), each in `2..=MAX_VAL_SAMPLES`.
    pub equal_error: Option<Vec<u32>>,
    /// Render the brute-force reference and report the error against it.
    pub references: bool,
    /// The paper's Table 1 configurations on scenes built from this one ([`table1`]); the
    /// sweep axes do not apply.
    pub table1: bool,
    pub out: PathBuf,
    /// Also measure the FMA-bound kernel against the gather ([`fma::measure`]).
    pub fma: bool,
    /// Also measure temporal stability ([`temporal::measure`]).
    pub temporal: bool,
    pub plots: bool,
}

/// The quick sweep's base resolution and the axes it sweeps when none are given.
const QUICK_SIDE: u32 = 32;
const QUICK_SPARSE: [u32; 2] = [32, 128];
const QUICK_RSM: [u32; 2] = [8, 16];

impl BenchOptions {
    /// The base configuration (the scene's settings; with `quick`, 32 sparse points per mesh,
    /// R = 8 and 32x32 unless the sweep gives a resolution) and the configurations.
    pub fn configs(&self, description: &SceneDescription, scene: &Scene) -> Vec<Config> {
        let mut base = Config::new(
            scene.settings.rsm_resolution,
            scene.settings.visibility.mode,
            scene.settings.glossy,
            description.camera.width,
            description.camera.height,
        );
        let mut sweep = self.sweep.clone();
        if self.quick {
            base.sparse_points_per_mesh = Some(QUICK_SPARSE[0]);
            base.rsm_resolution = QUICK_RSM[0];
            (base.width, base.height) = (QUICK_SIDE, QUICK_SIDE);
            if sweep == Sweep::default() {
                sweep.sparse_points = Some(QUICK_SPARSE.to_vec());
                sweep.rsm_resolution = Some(QUICK_RSM.to_vec());
                sweep.occlusion = Some(vec![Occlusion::Off, Occlusion::Disks]);
            }
        }
        sweep.configs(&base, self.grid)
    }
}

/// What a renderer is built for: sparse points per mesh, RSM resolution, glossy.
/// What is decided when the scene loads: sparse points per mesh, neighbours, adaptive
/// hundredths, subdivision.
type Placement = (Option<u32>, Option<u32>, Option<u32>, Option<u32>);

/// The sparse method's settings that need a new renderer but not a new scene: near field,
/// glossy interpolation, kernel, bound.
type Shading = (Option<u32>, Option<GlossyInterpolation>, Option<InterpolationKernel>, Option<LightBound>);

/// What needs a new renderer: the placement, the shading, RSM size, glossy.
type RendererKey = (Placement, Shading, u32, bool);

/// Run the sweep and write `results.json`, `results.csv` and (with `plots`) the plots into
/// `options.out`. `progress` is told each configuration as it starts.
pub fn run(gpu: &Gpu, options: &BenchOptions, progress: &mut dyn FnMut(&str)) -> Result<BenchResults, BenchError> {
    if let Some(exact) = &options.exact {
        exact.check().map_err(|message| {
            let (flag, why) = message.split_once(": ").unwrap_or(("--reference", message.as_str()));
            flag_error(flag, why)
        })?;
    }
    match (&options.equal_error, &options.exact) {
        (Some(_), None) => return Err(flag_error("--equal-error", "needs --reference exact")),
        (Some(samples), Some(_)) => {
            let max = crate::twin::exact_cpu::MAX_VAL_SAMPLES;
            if let Some(n) = samples.iter().find(|n| !(2..=max).contains(*n)) {
                return Err(flag_error("--equal-error", format!("sample counts must be in 2..={max}, got {n}")));
            }
            if samples.is_empty() {
                return Err(flag_error("--equal-error", "needs at least one sample count"));
            }
        }
        _ => {}
    }
    let path = &options.scene;
    let text = std::fs::read_to_string(path).map_err(|source| BenchError::Read { path: path.clone(), source })?;
    let scene_error = |source| BenchError::Scene { path: path.clone(), source };
    let description = SceneDescription::from_json_str(&text).map_err(scene_error)?;
    let base_dir = path.parent().unwrap_or_else(|| Path::new(".")).to_path_buf();
    let scene = Scene::from_description(&description, &base_dir).map_err(scene_error)?;
    if scene.light.is_none() {
        return Err(flag_error(
            &path.display().to_string(),
            "light: required by `bench` (its VALs come from the spot light's RSM)",
        ));
    }
    std::fs::create_dir_all(&options.out)
        .map_err(|e| flag_error("--out", format!("creating {}: {e}", options.out.display())))?;
    let jobs = if options.table1 {
        let jobs = table1::jobs(&description, &scene, options.quick);
        // The built scenes, for runs of single configurations (`bench <file> --no-references`).
        for job in &jobs {
            let file = options.out.join(format!("{}.json", job.variant));
            let d = table1::with_absolute_paths(&job.description, &base_dir);
            write_file(&file, serde_json::to_string_pretty(&d).expect("scenes serialise").as_bytes())?;
        }
        jobs
    } else {
        vec![Job { variant: "scene".to_owned(), configs: options.configs(&description, &scene), description }]
    };
    let mut results = Vec::new();
    let mut per_pixel_ism = Vec::new();
    let mut curves = Vec::new();
    let mut timing = None;
    let mut base_scene = None;
    for job in &jobs {
        let mut out = JobOutputs { results: &mut results, brute_force_ism: &mut per_pixel_ism, curves: &mut curves };
        let base = run_job(gpu, options, job, &base_dir, &mut out, progress).map_err(|e| match e {
            BenchError::Scene { source, .. } => BenchError::Scene { path: path.clone(), source },
            e => e,
        })?;
        base_scene.get_or_insert(base);
    }
    for r in &results {
        timing.get_or_insert(r.timing);
    }
    // The extra measurements use the first job's base configuration (its first).
    let base_scene = base_scene.unwrap_or(scene);
    // The extra measurements use the base configuration (the first).
    let fma = if options.fma {
        progress("FMA-bound kernel and gather variants");
        Some(fma::measure(gpu, &base_scene, options.quick)?)
    } else {
        None
    };
    let temporal = if options.temporal {
        progress("temporal stability");
        Some(temporal::measure(gpu, &base_scene, options.quick)?)
    } else {
        None
    };
    let results = BenchResults {
        scene: base_scene.meshes.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join("+"),
        adapter: gpu.adapter_name(),
        timing: timing.unwrap_or(if gpu.timestamps { TimingSource::GpuTimestamps } else { TimingSource::WallClock }),
        gpu_memory_note: GPU_MEMORY_NOTE,
        mode: if options.table1 {
            "table1"
        } else if options.grid {
            "grid"
        } else {
            "one_axis_at_a_time"
        },
        quick: options.quick,
        exact_val_stride: options.exact.map(|e| e.val_stride),
        exact_estimator: options.exact.map(|e| e.estimator()),
        configs: results,
        brute_force_ism: per_pixel_ism,
        equal_error_curves: curves,
        fma,
        temporal,
    };
    write_results(&options.out, &results)?;
    if options.plots {
        plot::write_all(&options.out, &results)
            .map_err(|message| BenchError::Write { path: options.out.clone(), message })?;
    }
    Ok(results)
}

/// Scenes and configurations to run: the scene file with the sweep's configurations, or the
/// scenes [`table1`] builds.
pub struct Job {
    /// `scene`, or which built scene (e.g. `table1_200k`).
    pub variant: String,
    pub description: SceneDescription,
    pub configs: Vec<Config>,
}

/// What [`run_job`] appends to.
struct JobOutputs<'a> {
    results: &'a mut Vec<ConfigResult>,
    brute_force_ism: &'a mut Vec<BruteForceIsmResult>,
    curves: &'a mut Vec<equal_error::EqualErrorCurve>,
}

/// Run `job`'s configurations, appending to `out`; returns the scene of its first
/// configuration (the base of the extra measurements).
fn run_job(
    gpu: &Gpu,
    options: &BenchOptions,
    job: &Job,
    base_dir: &Path,
    out: &mut JobOutputs<'_>,
    progress: &mut dyn FnMut(&str),
) -> Result<Scene, BenchError> {
    let JobOutputs { results, brute_force_ism, curves } = out;
    let scene_error = |source| BenchError::Scene { path: PathBuf::new(), source };
    // Group by what needs a new renderer (sparse points, RSM size, glossy), then by size.
    let mut groups: Vec<(RendererKey, Vec<Config>)> = Vec::new();
    for c in &job.configs {
        let key = (
            (c.sparse_points_per_mesh, c.neighbours, c.adaptive_percent, c.subdivision),
            (c.near_field, c.glossy_interpolation, c.kernel, c.bound),
            c.rsm_resolution,
            c.glossy,
        );
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, g)) => g.push(*c),
            None => groups.push((key, vec![*c])),
        }
    }
    // Scenes by what is decided at load: sparse points, neighbours, adaptive candidates.
    let mut scenes: HashMap<Placement, Scene> = HashMap::new();
    let mut base_scene = None;
    for ((placement, shading, rsm, glossy), group) in groups {
        let (sparse, neighbours, adaptive, subdivision) = placement;
        let (near_field, glossy_interpolation, kernel, bound) = shading;
        let mut scene = match scenes.get(&placement) {
            Some(s) => s.clone(),
            None => {
                let mut d = job.description.clone();
                if let Some(n) = sparse {
                    d.meshes.iter_mut().for_each(|m| m.sparse_points = n);
                }
                if let Some(k) = neighbours {
                    d.settings.tuning.interpolation_neighbours = Some(k);
                }
                if let Some(a) = adaptive {
                    d.settings.tuning.sparse.get_or_insert_default().adaptive = Some(a as f32 / 100.0);
                }
                if let Some(n) = subdivision {
                    d.settings.tuning.sparse.get_or_insert_default().subdivision = Some(n as f32);
                }
                let s = Scene::from_description(&d, base_dir).map_err(scene_error)?;
                scenes.insert(placement, s.clone());
                s
            }
        };
        scene.settings.rsm_resolution = rsm;
        scene.settings.glossy = glossy;
        if let Some(n) = near_field {
            scene.settings.sparse.near_field = n as f32;
        }
        if let Some(g) = glossy_interpolation {
            scene.settings.sparse.glossy_interpolation = g;
        }
        if let Some(k) = kernel {
            scene.settings.sparse.kernel = k;
        }
        if let Some(b) = bound {
            scene.settings.sparse.bound = b;
        }
        scene.settings.visibility.mode = group[0].occlusion;
        base_scene.get_or_insert_with(|| scene.clone());
        let mut renderer = Renderer::new(gpu, &scene)?;
        let mut sizes: Vec<(u32, u32)> = group.iter().map(|c| (c.width, c.height)).collect();
        sizes.dedup();
        for (w, h) in sizes {
            let mut sparse_frames = Vec::new();
            for c in group.iter().filter(|c| (c.width, c.height) == (w, h)) {
                progress(&format!("{}: {}", job.variant, describe(c)));
                let ism = c.ism_settings(&scene.settings.visibility.ism);
                ism.validate("settings.ism").map_err(|e| flag_error("--sweep", format!("{}: {e}", describe(c))))?;
                let clusters = c.clusters.apply(&scene.settings.visibility.clusters);
                clusters
                    .validate("settings.clusters")
                    .map_err(|e| flag_error("--sweep", format!("{}: {e}", describe(c))))?;
                renderer.set_visibility(VisibilitySettings {
                    mode: c.occlusion,
                    clusters,
                    ism,
                    ..scene.settings.visibility
                });
                let frame = compare::sparse_frame(gpu, &mut renderer, w, h)?;
                sparse_frames.push((*c, frame, gpu.memory_in_use()));
            }
            let brute = match options.references {
                true => Some(compare::brute_force_frame(gpu, &mut renderer, w, h)?),
                false => None,
            };
            let exact = match &options.exact {
                Some(exact) => Some(compare::exact_reference(gpu, &mut renderer, w, h, exact)?),
                None => None,
            };
            // The per-pixel ISM point: once per `ism` settings the sparse `ism` configurations
            // of this size used.
            if options.references {
                let mut seen: Vec<IsmSettings> = Vec::new();
                for c in group.iter().filter(|c| (c.width, c.height) == (w, h) && c.occlusion == Occlusion::Ism) {
                    let ism = c.ism_settings(&scene.settings.visibility.ism);
                    if seen.contains(&ism) {
                        continue;
                    }
                    seen.push(ism);
                    progress(&format!("{}: brute_force_ism for {}", job.variant, describe(c)));
                    renderer.set_visibility(VisibilitySettings { mode: Occlusion::Ism, ism, ..renderer.visibility() });
                    let frame = renderer.render(gpu, Method::BruteForceIsm, w, h)?;
                    let ism_stages: Vec<&str> =
                        frame.indirect_stages.iter().copied().filter(|s| *s != stage::BRUTE_FORCE).collect();
                    brute_force_ism.push(BruteForceIsmResult {
                        variant: job.variant.clone(),
                        config: *c,
                        ism,
                        timing: frame.timings.source,
                        stages_ms: frame.timings.stages.clone(),
                        ism_ms: frame.timings.total_of(&ism_stages),
                        indirect_ms: frame.indirect_ms(),
                        vs_brute_force: brute.as_ref().map(|b| compare::indirect_error(&frame.indirect, &b.indirect)),
                        vs_exact: exact.as_ref().map(|x| compare::indirect_error(&frame.indirect, x.indirect())),
                        rel_rmse_vs_exact_corrected: exact.as_ref().and_then(|x| x.corrected_rel_rmse(&frame.indirect)),
                    });
                }
            }
            let curve = match (&options.equal_error, &exact) {
                (Some(samples), Some(reference)) => {
                    let label = format!("{}: R {rsm}, glossy {glossy}, {w}x{h}", job.variant);
                    progress(&format!("{label}: converging estimator, samples {samples:?}"));
                    curves.push(equal_error::measure(label, gpu, &mut renderer, w, h, reference, samples)?);
                    curves.last()
                }
                _ => None,
            };
            renderer.release_reference_passes();
            for (config, frame, memory) in sparse_frames {
                let sparse_indirect_ms = frame.indirect_ms();
                let brute_force_ms = brute.as_ref().map(Rendered::indirect_ms);
                let gather_ms = frame.timings.total_of(&[stage::GATHER]);
                let interactions = frame.val_count as f64 * scene.sparse_point_count() as f64;
                let mut result = ConfigResult {
                    variant: job.variant.clone(),
                    config,
                    glossy_active: renderer.glossy(),
                    interpolation_neighbours: scene.settings.interpolation_neighbours,
                    sparse_points: scene.sparse_point_count(),
                    triangles: scene.triangle_count(),
                    vertices: scene.vertex_count(),
                    vals: frame.val_count,
                    pixels: w as u64 * h as u64,
                    covered_pixels: frame.indirect.coverage(),
                    timing: frame.timings.source,
                    frame_ms: frame.timings.stages.iter().map(|(_, ms)| ms).sum(),
                    stages_ms: frame.timings.stages.clone(),
                    sparse_indirect_ms,
                    brute_force_ms,
                    speedup: brute_force_ms.map(|b| b / sparse_indirect_ms),
                    gather_interactions_per_s: interactions / (gather_ms * 1e-3),
                    gpu_memory: memory,
                    gpu_memory_bytes: memory.total_bytes(),
                    vs_brute_force: brute.as_ref().map(|b| compare::indirect_error(&frame.indirect, &b.indirect)),
                    vs_exact: exact.as_ref().map(|x| compare::indirect_error(&frame.indirect, x.indirect())),
                    exact_ms: exact.as_ref().map(|x| x.ms()),
                    exact_device: exact.as_ref().map(|x| x.device),
                    exact_rel_stderr: exact.as_ref().and_then(|x| x.rel_stderr()),
                    rel_rmse_vs_exact_corrected: exact.as_ref().and_then(|x| x.corrected_rel_rmse(&frame.indirect)),
                    exact_rays_per_s: exact.as_ref().and_then(|x| x.rays_per_s()),
                    at_equal_error: None,
                    paper_fps: table1::paper_fps(&job.variant, &config, scene.sparse_point_count()),
                };
                result.at_equal_error =
                    curve.and_then(|c| equal_error::at_error(&c.points, result.error_vs_exact()?, sparse_indirect_ms));
                results.push(result);
            }
        }
    }
    Ok(base_scene.expect("a job has configurations"))
}
