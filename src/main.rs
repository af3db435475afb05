//! `avatarm`: the command line (robot check, desktop preview, headless replay, benches).

fn main() -> std::process::ExitCode {
    avatarm::cli::main()
}
