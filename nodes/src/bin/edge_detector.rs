//! The `edge_detector` node (see nodes/README.md): `edge_detector --ros-args ...`.
fn main() -> std::process::ExitCode {
    xsurf_nodes::host::main("edge_detector")
}
