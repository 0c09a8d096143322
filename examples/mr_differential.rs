//! The fast differential pass against the exact one on a recording: per frame, the exact
//! pass's time (the replay's `differential` stage), then the fast pass's time on the same
//! receivers and VALs and how its sums agree with the exact ones
//! (`mr::differential::Agreement`), for the default parameters and any others asked for.
//!
//! `cargo run --release --example mr_differential -- [SCENE] [RECORDING] [FRAME ...]`
//! (default: `fixtures/scenes/mr_bunny_differential.json` on `fixtures/recordings/tum_fr1_xyz`,
//! every frame). `FAST="16,4,8,0.03,1.1,4;32,4,4,0.05,1.1,16,0"` adds parameter sets (group size,
//! reach, adaptive spacing, change spread, irradiance ratio, re-emitter group size and, when
//! given, the faint members' ray share: `mr::differential::FastSettings`).
//! The fast pass runs where `settings.mr.device` puts it (the CPU on CPU adapters).
//! `ORACLE=1` instead fills the fast pass's adaptive receivers with the exact pass's sums (its
//! rows say "interpolation only" where the fast pass's time would be: the error the
//! interpolation between receivers makes by itself).
//! `REPEAT=n` runs the fast pass n times a frame and reports the least wall and CPU time (this
//! machine's noise only ever adds time).

use relume::gpu::Gpu;
use relume::gpu::differential::Differential;
use relume::gpu::differential::Receiver;
use relume::gpu::scene::{FlatScene, GpuScene};
use relume::mr::differential::{Agreement, FastSettings, adaptive_light, receiver_light};
use relume::mr::environment::Environment;
use relume::mr::{DIFFERENTIAL_STAGE, MrOptions, MrRenderer};
use relume::rgbd::recording::{Recording, RecordingOptions};
use relume::scene::settings::DifferentialMethod;
use relume::scene::{Scene, SceneDescription};
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

/// The CPU time this process has used, every thread (ms; Linux's `/proc/self/stat`, in clock
/// ticks of 10 ms; 0 elsewhere): less sensitive than wall time to what else shares the cores.
fn cpu_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command's closing parenthesis: state is field 3, utime 14, stime 15.
    let fields: Vec<&str> = stat.rsplit_once(')').map_or("", |(_, rest)| rest).split_whitespace().collect();
    let ticks = |k: usize| fields.get(k - 3).and_then(|f| f.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(14) + ticks(15)) * 10.0
}

/// The table's parameter cell: the order `FAST` takes them in.
fn parameters(f: &FastSettings) -> String {
    let (g, r, s, c, i, e, share) =
        (f.group_size, f.reach, f.spacing, f.change_spread, f.irradiance_ratio, f.emitter_group_size, f.ray_share);
    format!("{g},{r},{s},{c},{i},{e},{share}")
}

/// The table's last four cells: the fast sums' agreement with the exact ones.
fn agreement(a: &Agreement) -> String {
    format!("{:.4} | {:.4} | {:.3} | {:.3}", a.change_rel_rmse, a.unoccluded_rel_rmse, a.darkest_exact, a.darkest_fast)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene_path = Path::new(args.first().map_or("fixtures/scenes/mr_bunny_differential.json", String::as_str));
    let recording = args.get(1).map_or("fixtures/recordings/tum_fr1_xyz", String::as_str);
    let recording = Recording::open(Path::new(recording), &RecordingOptions::default())?;
    let frames: Vec<usize> = match args.len() > 2 {
        true => args[2..].iter().map(|s| s.parse()).collect::<Result<_, _>>()?,
        false => (0..recording.len()).collect(),
    };
    let mut variants = vec![FastSettings::default()];
    for v in std::env::var("FAST").unwrap_or_default().split(';').filter(|v| !v.is_empty()) {
        let f: Vec<f32> = v.split(',').map(str::parse).collect::<Result<_, _>>()?;
        anyhow::ensure!(matches!(f.len(), 6 | 7), "FAST: six or seven numbers per set, got {v}");
        variants.push(FastSettings {
            emitter_group_size: f[5] as usize,
            group_size: f[0] as usize,
            reach: f[1],
            spacing: f[2] as u32,
            change_spread: f[3],
            irradiance_ratio: f[4],
            ray_share: f.get(6).copied().unwrap_or(relume::mr::differential::RAY_SHARE),
        });
    }
    let repeat: usize = std::env::var("REPEAT").ok().and_then(|v| v.parse().ok()).unwrap_or(1).max(1);
    let gpu = Gpu::new()?;
    let mut scene = Scene::load(scene_path)?;
    scene.settings.mr.differential_method = Some(DifferentialMethod::Exact);
    let text = std::fs::read_to_string(scene_path)?;
    let environment = SceneDescription::from_json_str(&text)?.settings.environment;
    let environment = Environment::from_settings(&environment, scene_path.parent().unwrap_or(Path::new(".")))?;
    let k = recording.intrinsics();
    let options = MrOptions { width: k.width, height: k.height, exposure: 1.0, accumulate: None };
    let mut exact = MrRenderer::new(&gpu, &scene, options)?;
    exact.set_environment(environment);
    let gpu_scene = GpuScene::new(&gpu, FlatScene::from_scene(&scene))?;
    let mut pass = Differential::on(&gpu, &gpu_scene, scene.settings.mr.device)?;
    println!("adapter: {}; fast pass on the {:?}", gpu.adapter_name(), pass.device());
    println!(
        "| frame | receivers | exact ms | fast parameters | computed | fast ms | fast CPU ms | change rel RMSE | E rel RMSE | darkest exact | darkest fast |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut rows: Vec<Vec<(f64, f64, Agreement)>> = vec![Vec::new(); variants.len()];
    for i in frames {
        let frame = recording.frame(i)?;
        let e = exact.render_frame(&gpu, &frame)?;
        let Some(d) = &e.differential else {
            anyhow::bail!("frame {i}: the differential pass did not run (is settings.mr.differential on?)");
        };
        let exact_ms = e.timings.stages.iter().find(|(s, _)| s == DIFFERENTIAL_STAGE).map_or(0.0, |(_, ms)| *ms);
        if std::env::var("ORACLE").is_ok() {
            // The adaptive receivers filled with the exact pass's own sums where they compute:
            // the error the interpolation alone makes, whatever the sums.
            let key = |r: &Receiver| [r.position, r.normal].map(|v| v.to_array().map(f32::to_bits));
            let index: HashMap<_, _> = d.grid.receivers.iter().enumerate().map(|(i, r)| (key(r), i)).collect();
            for fast in &variants {
                let exact_at = |rs: &[Receiver]| {
                    Ok::<_, std::convert::Infallible>(rs.iter().map(|r| d.light[index[&key(r)]]).collect())
                };
                let Ok((light, counts)) = adaptive_light(&d.grid, fast, exact_at);
                let a = Agreement::of(&d.light, &light, &d.visible);
                println!(
                    "| {i} | {} | {exact_ms:.0} | {} | {} | interpolation only | – | {} |",
                    d.light.len(),
                    parameters(fast),
                    counts.computed,
                    agreement(&a)
                );
            }
            continue;
        }
        for (v, fast) in variants.iter().enumerate() {
            // The least of `REPEAT` runs (1 unless set): this machine's noise only ever adds time.
            let (mut fast_ms, mut fast_cpu_ms) = (f64::MAX, f64::MAX);
            let method = (DifferentialMethod::Fast, fast);
            let mut run = || -> anyhow::Result<_> {
                let (start, cpu) = (Instant::now(), cpu_ms());
                let out =
                    receiver_light(&mut pass, &gpu, &gpu_scene, &d.grid, &d.vals, d.real_count, d.bounds, method)?;
                fast_ms = fast_ms.min(start.elapsed().as_secs_f64() * 1e3);
                fast_cpu_ms = fast_cpu_ms.min(cpu_ms() - cpu);
                Ok(out)
            };
            let (light, counts) = run()?;
            for _ in 1..repeat {
                run()?;
            }
            let a = Agreement::of(&d.light, &light, &d.visible);
            println!(
                "| {i} | {} | {exact_ms:.0} | {} | {} | {fast_ms:.0} | {fast_cpu_ms:.0} | {} |",
                d.light.len(),
                parameters(fast),
                counts.computed,
                agreement(&a)
            );
            if std::env::var("COUNTS").is_ok() {
                println!("  {counts:?}");
            }
            rows[v].push((exact_ms, fast_ms, a));
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    println!();
    for (fast, rows) in variants.iter().zip(&rows) {
        if rows.is_empty() {
            continue;
        }
        let (e, f) = (median(rows.iter().map(|r| r.0).collect()), median(rows.iter().map(|r| r.1).collect()));
        let worst_change = rows.iter().map(|r| r.2.change_rel_rmse).fold(0.0, f64::max);
        let worst_darkest = rows.iter().map(|r| r.2.darkest_rel_error()).fold(0.0f32, f32::max);
        println!(
            "{fast:?}: median exact {e:.0} ms, fast {f:.0} ms ({:.1}x less); worst change rel RMSE {worst_change:.4}, \
             worst darkest rel error {worst_darkest:.4}",
            e / f.max(1e-9)
        );
    }
    Ok(())
}
