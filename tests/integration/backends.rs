//! Every technique on every backend wgpu offers here: Vulkan (lavapipe) and GL (llvmpipe through
//! EGL, what wgpu picks where no Vulkan driver is installed). `relume compare --reference exact`
//! renders the sparse method with every visibility mode (off, the disks' sum and product,
//! clusters, imperfect shadow maps), the brute force, the brute force through ISMs and the exact
//! reference, so one run per backend exercises every pipeline; the two backends run the same
//! CPU rasteriser underneath, so their figures must agree: to 0.01 % where the computation is
//! deterministic, and within 5 % for the modes that group VALs (clusters, ISMs, the brute force
//! through ISMs), whose float atomics sum in a different order on every run: their errors
//! vary by 1-3 % between two runs on one backend.

use super::fixture;
use std::process::Command;

fn compare_on(backend: &str) -> serde_json::Value {
    let scene = fixture("scenes/cornell_bunny_small.json");
    let o = Command::new(env!("CARGO_BIN_EXE_relume"))
        .args(["compare", scene.to_str().unwrap(), "--width", "12", "--height", "12", "--reference", "exact"])
        .env("WGPU_BACKEND", backend)
        .output()
        .expect("running relume");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "compare on {backend} failed: {stderr}");
    assert!(!stderr.contains("panicked"), "{backend}: {stderr}");
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{backend}: one JSON object: {e}"))
}

#[test]
fn every_technique_runs_on_vulkan_and_gl_with_the_same_figures() {
    let vulkan = compare_on("vulkan");
    let gl = compare_on("gl");
    assert!(vulkan["adapter"].as_str().unwrap().ends_with("(Vulkan)"), "{}", vulkan["adapter"]);
    assert!(gl["adapter"].as_str().unwrap().ends_with("(Gl)"), "{}", gl["adapter"]);
    let errors = |v: &serde_json::Value| -> Vec<(String, f64)> {
        let mut e = vec![("sparse vs brute force".to_owned(), v["indirect_rel_rmse"].as_f64().unwrap())];
        for m in v["modes_vs_exact"].as_array().expect("every mode against exact") {
            e.push((m["mode"].as_str().unwrap().to_owned(), m["rel_rmse"].as_f64().unwrap()));
        }
        for key in
            ["brute_force_vs_exact", "brute_force_ism_vs_exact", "brute_force_clusters_vs_exact", "default_vs_exact"]
        {
            e.push((key.to_owned(), v[key]["rel_rmse"].as_f64().unwrap_or_else(|| panic!("{key}: {v}"))));
        }
        e
    };
    let (on_vulkan, on_gl) = (errors(&vulkan), errors(&gl));
    assert_eq!(on_vulkan.len(), 10);
    for ((what, a), (_, b)) in on_vulkan.iter().zip(&on_gl) {
        let grouped =
            ["clusters", "ism", "brute_force_ism_vs_exact", "brute_force_clusters_vs_exact"].contains(&what.as_str());
        let rel = if grouped { 0.05 } else { 1e-4 };
        assert!(a.is_finite() && (a - b).abs() <= rel * a.max(1e-3), "{what}: Vulkan {a} vs GL {b}");
    }
}
