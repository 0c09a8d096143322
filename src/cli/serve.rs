//! `relume serve` and `relume openapi`.

use anyhow::Context;

pub fn run(config: relume::service::Config) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(relume::service::serve(config))?;
    Ok(())
}

pub fn openapi() -> anyhow::Result<()> {
    print!("{}", relume::service::openapi_json());
    Ok(())
}
