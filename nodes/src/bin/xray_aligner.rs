//! The `xray_aligner` node (see nodes/README.md): `xray_aligner --ros-args ...`.
fn main() -> std::process::ExitCode {
    xsurf_nodes::host::main("xray_aligner")
}
