//! `study`: the vshake command line. Thin: parse, dispatch, map the error chain to an exit code.
//!
//! Exit codes (docs/formats.md "Exit codes"): 0 success; 1 a run failed or the system did
//! (disk full, file too large); 2 bad input, naming the file, key or row; 128 + n a run stopped by
//! signal n (130 Ctrl-C, 143 SIGTERM), its file incomplete and resumable; 70 an internal error
//! (a panic: a bug in vshake).

use clap::Parser;
use std::sync::Mutex;

/// Exit code of an internal error (EX_SOFTWARE of sysexits.h).
const INTERNAL_ERROR: i32 = 70;

/// Where the panic hook leaves the message and place of a panic, for the report at the top.
static PANIC: Mutex<Option<String>> = Mutex::new(None);

fn main() {
    let cli = vshake::shell::cli::Cli::parse();
    vshake::shell::job::interrupt::ignore_file_size_signal();
    std::panic::set_hook(Box::new(|info| {
        let place = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        let what = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        // The latest panic: one caught on the way (a corrupt Parquet file) is replaced by the
        // one that reaches the top.
        if let Ok(mut p) = PANIC.lock() {
            *p = Some(format!("{what}{place}"));
        }
    }));
    let result = std::panic::catch_unwind(|| {
        // How the tests reach this path: no command panics on purpose.
        if std::env::var_os("VSHAKE_PANIC_FOR_TEST").is_some() {
            panic!("VSHAKE_PANIC_FOR_TEST is set");
        }
        vshake::shell::dispatch(cli)
    });
    let Ok(result) = result else {
        let what = PANIC
            .lock()
            .ok()
            .and_then(|p| p.clone())
            .unwrap_or_else(|| "a panic".into());
        eprintln!("internal error (a bug in vshake, please report it with the command that caused it): {what}");
        std::process::exit(INTERNAL_ERROR);
    };
    if let Err(e) = result {
        // A closed pipe (`study params | head`) is not an error worth a message.
        if e.chain().any(|c| {
            c.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
        }) {
            std::process::exit(0);
        }
        if let Some(i) = e.downcast_ref::<vshake::shell::job::interrupt::Interrupted>() {
            eprintln!("{i}");
            std::process::exit(i.exit_code());
        }
        eprintln!("error: {e:#}");
        std::process::exit(vshake::shell::exit_code(&e));
    }
}
