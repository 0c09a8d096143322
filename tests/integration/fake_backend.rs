//! A GPU thread without a GPU, for the service's tests: scheduling, limits and error paths are
//! tested with known render times and without an adapter; scenes are still parsed and loaded
//! for real.

use std::collections::HashSet;
use std::time::Duration;

use relume::gpu::timing::{StageTimings, TimingSource};
use relume::image::LinearImage;
use relume::mr::environment::Environment;
use relume::renderer::Rendered;
use relume::scene::Scene;
use relume::service::gpu_worker::{Frame, RenderJob, StreamFrameJob};
use relume::service::{Backend, WorkerError};

/// A GPU thread without a GPU: every render takes `render_time` and is grey.
pub(super) struct FakeBackend {
    render_time: Duration,
    scenes: HashSet<String>,
}

impl FakeBackend {
    pub(super) fn new(render_time: Duration) -> FakeBackend {
        FakeBackend { render_time, scenes: HashSet::new() }
    }

    fn frame(&self, id: &str, width: u32, height: u32) -> Result<Frame, WorkerError> {
        if !self.scenes.contains(id) {
            return Err(WorkerError::SceneNotFound(id.to_owned()));
        }
        std::thread::sleep(self.render_time);
        let image = LinearImage { width, height, pixels: vec![[0.2, 0.2, 0.2, 1.0]; (width * height) as usize] };
        let timings = StageTimings {
            source: TimingSource::WallClock,
            stages: vec![("fake".to_owned(), self.render_time.as_secs_f64() * 1e3)],
        };
        Ok((
            Rendered {
                direct: image.clone(),
                indirect: image,
                timings,
                indirect_stages: Vec::new(),
                val_count: 0,
                exact_rounds: 0,
                error_estimate: None,
            },
            None,
        ))
    }
}

impl Backend for FakeBackend {
    fn adapter(&self) -> String {
        "fake backend (no GPU)".to_owned()
    }

    fn add_scene(&mut self, id: &str, _: Scene, _: Environment) -> Result<(), WorkerError> {
        self.scenes.insert(id.to_owned());
        Ok(())
    }

    fn remove_scene(&mut self, id: &str) -> bool {
        self.scenes.remove(id)
    }

    fn render(&mut self, id: &str, job: &RenderJob) -> Result<Frame, WorkerError> {
        self.frame(id, job.width, job.height)
    }

    fn render_stream_frame(&mut self, id: &str, job: &StreamFrameJob) -> Result<Frame, WorkerError> {
        let k = job.frame.intrinsics;
        let (width, height) = job.camera.map_or((k.width, k.height), |c| (c.width, c.height));
        self.frame(id, width, height)
    }
}
