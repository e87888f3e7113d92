//! The `mesher` node (see nodes/README.md): `mesher --ros-args ...`.
fn main() -> std::process::ExitCode {
    xsurf_nodes::host::main("mesher")
}
