//! The `triangulator` node (see nodes/README.md): `triangulator --ros-args ...`.
fn main() -> std::process::ExitCode {
    xsurf_nodes::host::main("triangulator")
}
