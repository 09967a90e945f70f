//! The `talus` binary: the library's command line ([`talus::cli`]).

fn main() -> std::process::ExitCode {
    talus::cli::main()
}
