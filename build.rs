//! Compiles `proto/relume.proto` (the WebSocket stream's messages) to Rust with prost. protox
//! parses the file in Rust, so no `protoc` binary is needed.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=proto/relume.proto");
    let descriptors = protox::compile(["proto/relume.proto"], ["proto"])?;
    prost_build::Config::new().compile_fds(descriptors)?;
    Ok(())
}
