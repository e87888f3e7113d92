//! The `c_arm_pose` node (see nodes/README.md): `c_arm_pose --ros-args ...`.
fn main() -> std::process::ExitCode {
    xsurf_nodes::host::main("c_arm_pose")
}
