//! The `merger` node (see nodes/README.md): `merger --ros-args ...`.
fn main() -> std::process::ExitCode {
    xsurf_nodes::host::main("merger")
}
