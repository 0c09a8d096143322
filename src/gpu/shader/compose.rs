//! The one way relume assembles a shader's WGSL: [`Wgsl`], a builder that emits constants
//! from Rust values (formatted so WGSL parses them) and appends WGSL text, in order.
//!
//! ```
//! use relume::gpu::shader::Wgsl;
//! let source = Wgsl::new()
//!     .u32("ROWS", 2)
//!     .f32("RADIUS", 0.25)
//!     .bool("GLOSSY", true)
//!     .include("fn rows() -> u32 { return ROWS; }")
//!     .finish();
//! assert_eq!(source, "const ROWS: u32 = 2u;\nconst RADIUS: f32 = 2.5e-1;\nconst GLOSSY: bool = true;\nfn rows() -> u32 { return ROWS; }\n");
//! ```
//!
//! # Why a small builder and not a shader composer
//!
//! Established composers were weighed:
//!
//! - `naga_oil` (Bevy's; 0.23 depends on naga 30, so it would fit wgpu 30) composes modules
//!   at the level of naga IR: every shared file would gain a `#define_import_path` and every
//!   user `#import` lines, and its name mangling would rename the shared structs and functions
//!   in the output. Its shader definitions take booleans and integers only, while relume's
//!   passes are specialised mostly by `f32` constants (radii, biases, epsilons generated from
//!   the CPU twins' Rust constants). It would also make naga a runtime dependency and give a
//!   `naga::Module` instead of the WGSL text that the naga layout test reads and wgpu takes.
//! - `wesl` (the WGSL extension language) asks for the same rewrite of the shader files into its
//!   module syntax, and specialises with its own conditional compilation, not Rust values.
//!
//! relume's shaders need two things only: constants generated from Rust, and files
//! concatenated in a fixed order (every file declares what it uses before the next one uses it).
//! Both fit in this module without touching a line of WGSL, so the generated sources stay the
//! same shaders as before. What the builder adds over `format!`: one formatting of each type
//! (`u32` with `u`, `f32` in `e` notation, never `inf` or `NaN`), and a refusal of a constant
//! declared twice, whether by the builder or by an included file's module-scope `const`, with the
//! name in the panic, before naga reports a redefinition far from its cause.
//!
//! A few passes generate a function in Rust (an unrolled loop over receivers, a receiver
//! index); they write its text with `format!` and append it with [`Wgsl::include`] like a file.
//! The sources at the default parameters were compared before and after the move to the
//! builder: the same lines in the same order, blank lines and the digits of `f32` literals
//! aside (`0.5` is now `5e-1`).

use std::collections::BTreeSet;

/// A WGSL source under construction: constants and included text, in the order added.
#[derive(Clone, Debug, Default)]
pub struct Wgsl {
    source: String,
    /// Every module-scope constant declared so far (by the builder or an included file).
    constants: BTreeSet<String>,
}

impl Wgsl {
    pub fn new() -> Self {
        Self::default()
    }

    /// `const name: u32 = {value}u;`
    pub fn u32(self, name: &str, value: u32) -> Self {
        self.constant(name, "u32", &format!("{value}u"))
    }

    /// `const name: f32 = {value:e};`. Panics unless `value` is finite (WGSL has no `inf` or
    /// `NaN` literal).
    pub fn f32(self, name: &str, value: f32) -> Self {
        self.constant(name, "f32", &f32_literal(name, value))
    }

    /// `const name: bool = {value};`
    pub fn bool(self, name: &str, value: bool) -> Self {
        self.constant(name, "bool", if value { "true" } else { "false" })
    }

    /// `const name: vec3<f32> = vec3<f32>(x, y, z);`, each component as [`Wgsl::f32`] writes it.
    pub fn vec3_f32(self, name: &str, value: [f32; 3]) -> Self {
        let [x, y, z] = value.map(|c| f32_literal(name, c));
        self.constant(name, "vec3<f32>", &format!("vec3<f32>({x}, {y}, {z})"))
    }

    /// `const name: ty = expression;` for a constant computed in WGSL from earlier ones (e.g.
    /// `ROW` as `2u * NEIGHBOURS`).
    pub fn expression(self, name: &str, ty: &str, expression: &str) -> Self {
        self.constant(name, ty, expression)
    }

    /// Appends `text` (a WGSL file, or a fragment generated in Rust), on lines of its own
    /// (nothing when it is empty). Its
    /// module-scope constants (`const` at the start of a line) join the declared ones: one
    /// declared before panics.
    pub fn include(mut self, text: &str) -> Self {
        if text.is_empty() {
            return self;
        }
        for line in text.lines() {
            if let Some(rest) = line.strip_prefix("const ") {
                let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                self.declare(&name);
            }
        }
        if !self.source.is_empty() && !self.source.ends_with('\n') {
            self.source.push('\n');
        }
        self.source.push_str(text);
        if !text.ends_with('\n') {
            self.source.push('\n');
        }
        self
    }

    /// The source.
    pub fn finish(self) -> String {
        self.source
    }

    fn constant(mut self, name: &str, ty: &str, value: &str) -> Self {
        assert!(
            name.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'),
            "WGSL constant name `{name}` is not an identifier"
        );
        self.declare(name);
        self.source.push_str(&format!("const {name}: {ty} = {value};\n"));
        self
    }

    fn declare(&mut self, name: &str) {
        assert!(self.constants.insert(name.to_owned()), "WGSL constant `{name}` declared twice");
    }
}

/// `value` as a WGSL float literal: Rust's shortest round-trip digits in `e` notation (`1e-3`,
/// `3e38`, `-2.5e-1`), which WGSL parses to the same `f32`.
fn f32_literal(name: &str, value: f32) -> String {
    assert!(value.is_finite(), "WGSL constant `{name}` = {value}: WGSL has no literal for it");
    format!("{value:e}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_are_formatted_as_wgsl_literals_in_order() {
        let source = Wgsl::new()
            .u32("A", 4_294_967_295)
            .f32("B", 1e-3)
            .f32("C", 3.0e38)
            .f32("D", -0.25)
            .f32("E", 0.0)
            .bool("F", false)
            .vec3_f32("G", [0.0, 1.0, -2.0])
            .expression("H", "u32", "2u * A")
            .finish();
        assert_eq!(
            source,
            "const A: u32 = 4294967295u;\nconst B: f32 = 1e-3;\nconst C: f32 = 3e38;\nconst D: f32 = -2.5e-1;\n\
             const E: f32 = 0e0;\nconst F: bool = false;\nconst G: vec3<f32> = vec3<f32>(0e0, 1e0, -2e0);\n\
             const H: u32 = 2u * A;\n"
        );
    }

    /// Every f32 literal reads back as the same f32 (WGSL's parse is Rust's for these digits).
    #[test]
    fn f32_literals_round_trip() {
        for v in [1e-30f32, f32::MIN_POSITIVE, 0.02, 1.0 / 3.0, 0.1, 12345.678, f32::MAX, -7.5e-12] {
            let text = f32_literal("X", v);
            assert!(!text.contains("inf") && !text.contains("NaN"), "{text}");
            assert_eq!(text.parse::<f32>().unwrap().to_bits(), v.to_bits(), "{text}");
        }
    }

    #[test]
    #[should_panic(expected = "WGSL has no literal")]
    fn infinity_is_refused() {
        let _ = Wgsl::new().f32("FAR", f32::INFINITY);
    }

    #[test]
    #[should_panic(expected = "WGSL has no literal")]
    fn nan_is_refused() {
        let _ = Wgsl::new().f32("X", f32::NAN);
    }

    #[test]
    #[should_panic(expected = "WGSL constant `ROW` declared twice")]
    fn a_constant_declared_twice_is_refused() {
        let _ = Wgsl::new().u32("ROW", 1).u32("ROW", 2);
    }

    #[test]
    #[should_panic(expected = "WGSL constant `TILE` declared twice")]
    fn a_constant_also_declared_by_an_included_file_is_refused() {
        let _ = Wgsl::new().u32("TILE", 8).include("// tiles\nconst TILE: u32 = 16u;\nfn f() {}\n");
    }

    /// A function-scope `const` (indented) is not a module-scope one.
    #[test]
    fn indented_consts_are_not_module_scope() {
        let source =
            Wgsl::new().u32("N", 2).include("fn f() -> u32 {\n    const N: u32 = 3u;\n    return N;\n}").finish();
        assert!(source.ends_with("return N;\n}\n"), "{source}");
    }

    #[test]
    fn included_text_keeps_its_order_on_lines_of_its_own() {
        let source = Wgsl::new().include("fn a() {}").u32("B", 1).include("fn c() {}\n").include("").finish();
        assert_eq!(source, "fn a() {}\nconst B: u32 = 1u;\nfn c() {}\n");
    }

    #[test]
    #[should_panic(expected = "is not an identifier")]
    fn names_must_be_identifiers() {
        let _ = Wgsl::new().u32("NOT A NAME", 1);
    }
}
