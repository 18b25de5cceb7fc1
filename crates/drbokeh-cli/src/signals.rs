//! SIGINT, SIGTERM and SIGHUP: remove this process's temporary outputs, then exit with
//! 128 + the signal number (130 for Ctrl-C), as a shell would report the default action.
//! Outputs already renamed into place are complete; nothing partial is left behind.

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
use signal_hook::iterator::Signals;

/// Starts the thread that waits for the signals. Errors (no signal support) are ignored:
/// the command still works, only without cleanup on interruption.
pub fn install() {
    let Ok(mut signals) = Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
        return;
    };
    let _ = std::thread::Builder::new()
        .name("drbokeh-signals".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                drbokeh::io::temps::remove_all();
                eprintln!("\ndrbokeh: interrupted (signal {sig}); temporary files removed");
                std::process::exit(128 + sig);
            }
        });
}
