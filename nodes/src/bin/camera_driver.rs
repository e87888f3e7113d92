//! The `camera_driver` node (see nodes/README.md): `camera_driver --ros-args ...`.
fn main() -> std::process::ExitCode {
    xsurf_nodes::host::main("camera_driver")
}
