//! `esgm-refsys-node`: serves one sensor or unit of the Autoware reference system's
//! esgm system file (`benches/refsys/refsys.toml`), started by the coordinator that
//! applies it. See `esgm_benches::refsys::node_program`.

fn main() -> std::process::ExitCode {
    esgm_benches::refsys::node_program::main()
}
