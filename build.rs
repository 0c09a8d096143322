//! Compiles `proto/relume.proto` (the WebSocket stream's messages) to Rust with prost. protox
//! parses the file in Rust, so no `protoc` binary is needed. Also lists the file's messages and
//! enums (`$OUT_DIR/relume.proto.txt`), which a test compares with the browser viewer's
//! descriptor (src/service/viewer/relume.proto.json).

use std::fmt::Write as _;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=proto/relume.proto");
    let descriptors = protox::compile(["proto/relume.proto"], ["proto"])?;
    let mut listing = String::new();
    for file in &descriptors.file {
        let package = format!(".{}.", file.package());
        let type_name = |name: &str| name.strip_prefix(&package).unwrap_or(name).to_owned();
        for enumeration in &file.enum_type {
            for value in &enumeration.value {
                writeln!(listing, "enum {} {} = {}", enumeration.name(), value.name(), value.number())?;
            }
        }
        let mut messages: Vec<_> = file.message_type.iter().map(|m| (m.name().to_owned(), m)).collect();
        while let Some((name, message)) = messages.pop() {
            messages.extend(message.nested_type.iter().map(|m| (format!("{name}.{}", m.name()), m)));
            for field in &message.field {
                let label = match (field.label().as_str_name(), field.proto3_optional()) {
                    ("LABEL_REPEATED", _) => "repeated ",
                    (_, true) => "optional ",
                    _ => "",
                };
                let ty = match field.type_name() {
                    "" => field.r#type().as_str_name().trim_start_matches("TYPE_").to_lowercase(),
                    named => type_name(named),
                };
                let oneof = match field.oneof_index {
                    Some(i) if !field.proto3_optional() => format!(" oneof {}", message.oneof_decl[i as usize].name()),
                    _ => String::new(),
                };
                writeln!(listing, "message {name} {label}{ty} {} = {}{oneof}", field.name(), field.number())?;
            }
        }
    }
    std::fs::write(std::path::Path::new(&std::env::var("OUT_DIR")?).join("relume.proto.txt"), listing)?;
    prost_build::Config::new().compile_fds(descriptors)?;
    Ok(())
}
