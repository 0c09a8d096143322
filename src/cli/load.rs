//! `relume load`: the service's load benchmark.

use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// A running server (http://host:port); default: one started in this process.
    #[arg(long)]
    server: Option<String>,
    #[command(flatten)]
    client: super::ServerClient,
    /// Concurrent streams (each on its own copy of --scene).
    #[arg(long, default_value_t = 2)]
    streams: usize,
    /// Concurrent HTTP render clients (on one copy of --http-scene).
    #[arg(long = "http", default_value_t = 2)]
    http_clients: usize,
    /// How long the clients send, s.
    #[arg(long, default_value_t = 30.0)]
    seconds: f64,
    /// Frames per second each stream sends.
    #[arg(long, default_value_t = 10.0)]
    fps: f64,
    #[arg(long, default_value = "fixtures/recordings/tum_fr1_xyz")]
    recording: PathBuf,
    /// The scene the streams relight.
    #[arg(long, default_value = "fixtures/scenes/mr_bunny.json")]
    scene: PathBuf,
    /// The scene the HTTP clients render (at its camera); its meshes are named by path
    /// inside the server's asset directory.
    #[arg(long, default_value = "fixtures/scenes/cornell_bunny_small.json")]
    http_scene: PathBuf,
    /// The server's asset directory as seen from here (the server started here serves it).
    #[arg(long, default_value = ".")]
    assets: PathBuf,
    /// Frames of the recording loaded and cycled through.
    #[arg(long, default_value_t = 8)]
    frames: usize,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    /// Soak test instead: one normal stream and HTTP client alone, then beside a hostile
    /// mix (floods, slow and idle sockets, bad stream messages, scene churn), each phase
    /// --seconds long, on loopback (docs/service.md "Load and soak tests").
    #[arg(long)]
    chaos: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let seconds = args.seconds;
    anyhow::ensure!(seconds.is_finite() && seconds > 0.0, "--seconds: must be a positive number, got {seconds}");
    let options = relume::service::load::LoadOptions {
        server: args.server,
        token: args.client.token.clone(),
        streams: args.streams,
        http_clients: args.http_clients,
        duration: std::time::Duration::from_secs_f64(seconds),
        fps: args.fps,
        recording: args.recording,
        stream_scene: args.scene,
        http_scene: args.http_scene,
        assets: args.assets,
        frames: args.frames,
        chaos: args.chaos,
        reconnect: args.client.reconnect(),
    };
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    if args.chaos {
        let report = runtime.block_on(relume::service::load::soak(&options))?;
        match args.json {
            true => println!("{}", serde_json::to_string_pretty(&report)?),
            false => println!("{}", relume::service::load::soak_table(&report)),
        }
        return Ok(());
    }
    let report = runtime.block_on(relume::service::load::run(&options))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("{}", relume::service::load::table(&report));
    }
    Ok(())
}
