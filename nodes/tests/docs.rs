//! The node documentation lists every declared parameter with its default, unit and range.
//! The tables in nodes/README.md are generated from the declarations: after changing a
//! parameter, `XSURF_BLESS=1 cargo test -p xsurf-nodes --test docs` rewrites them.
#![allow(clippy::unwrap_used)]

use xsurf_nodes::registry::{declarations, NODE_NAMES};
use xsurf_runtime::params::markdown_table;

/// The README's sections and their tables: each node's, then the host's.
fn tables() -> Vec<(String, String)> {
    let mut t: Vec<(String, String)> =
        NODE_NAMES.iter().map(|n| (format!("## {n}\n"), markdown_table(&declarations(n).unwrap()))).collect();
    t.push((
        "### Parameters of every node (the host's)\n".into(),
        markdown_table(&xsurf_runtime::dds::host_declarations()),
    ));
    t
}

/// `readme` with the first table after each section heading replaced by the generated one.
fn blessed(readme: &str) -> String {
    let mut s = readme.to_string();
    for (heading, table) in tables() {
        let Some(at) = s.find(&heading) else {
            // A new node: its section and table at the end, to be described by hand.
            s.push_str(&format!("\n{heading}\n{table}"));
            continue;
        };
        let start = at + s[at..].find("\n| parameter |").unwrap() + 1;
        let len = s[start..].split_inclusive('\n').take_while(|l| l.starts_with('|')).map(str::len).sum::<usize>();
        s.replace_range(start..start + len, &table);
    }
    s
}

#[test]
fn readme_lists_every_parameter_with_its_default() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/README.md");
    let readme = std::fs::read_to_string(path).unwrap();
    if std::env::var_os("XSURF_BLESS").is_some() {
        std::fs::write(path, blessed(&readme)).unwrap();
        return;
    }
    for (heading, t) in tables() {
        assert!(
            readme.contains(&t),
            "nodes/README.md: the parameter table of {heading:?} is out of date (XSURF_BLESS=1 cargo test -p \
             xsurf-nodes --test docs rewrites it); expected:\n{t}"
        );
    }
}

/// Defaults print as written (`0.012`), not as an `f32` widened to `f64`
/// (`0.012000000104308128`, which the docs and `--help` showed).
#[test]
fn defaults_print_as_written() {
    for node in NODE_NAMES {
        for d in declarations(node).unwrap_or_default() {
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
