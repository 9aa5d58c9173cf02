//! `study`: the vshake command line. Thin: parse, dispatch, map the error chain to an exit code.

use clap::Parser;

fn main() {
    let cli = vshake::shell::cli::Cli::parse();
    if let Err(e) = vshake::shell::dispatch(cli) {
        // A closed pipe (`study params | head`) is not an error worth a message.
        if e.chain().any(|c| c.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)) {
            std::process::exit(0);
        }
        eprintln!("error: {e:#}");
        std::process::exit(vshake::shell::exit_code(&e));
    }
}
