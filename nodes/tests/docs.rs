//! The node documentation lists every declared parameter with its default and unit.
#![allow(clippy::unwrap_used)]

use xsurf_nodes::components::{declarations, NODE_NAMES};

fn table(node: &str) -> Option<String> {
    let decls = declarations(node)?;
    let mut s = String::from("| parameter | type | default | unit | meaning |\n|---|---|---|---|---|\n");
    for d in decls {
        s.push_str(&format!(
            "| `{}` | {} | `{}` | {} | {} |\n",
            d.name,
            d.default.type_name(),
            d.default,
            d.unit,
            d.description
        ));
    }
    Some(s)
}

#[test]
fn readme_lists_every_parameter_with_its_default() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    for node in NODE_NAMES {
        if let Some(t) = table(node) {
            assert!(
                readme.contains(&t),
                "nodes/README.md: the parameter table of {node} is out of date; expected:\n{t}"
            );
        }
    }
}

/// `cargo test -p xsurf-nodes --test docs -- --ignored --nocapture` prints the tables.
/// Defaults print as written (`0.012`), not as an `f32` widened to `f64`
/// (`0.012000000104308128`, which the docs and `--help` showed).
#[test]
fn defaults_print_as_written() {
    for node in NODE_NAMES {
        for d in xsurf_nodes::components::declarations(node).unwrap_or_default() {
            let shown = d.default.to_string();
            let digits = shown.chars().filter(char::is_ascii_digit).count();
            assert!(
                !matches!(d.default, xsurf_runtime::params::ParamValue::Double(_)) || digits <= 8,
                "{node}: {} shows as {shown}",
                d.name
            );
        }
    }
}

#[test]
#[ignore]
fn print_parameter_tables() {
    for node in NODE_NAMES {
        if let Some(t) = table(node) {
            println!("### {node}\n\n{t}");
        }
    }
}
