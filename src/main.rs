fn main() -> std::process::ExitCode {
    l3::cli::main()
}
