//! `xsurf`: the offline tools (see `xsurf --help` and `nodes/src/cli/`).

fn main() -> std::process::ExitCode {
    xsurf_nodes::cli::main()
}
