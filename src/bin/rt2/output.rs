//! Writing to the terminal. `println!` and `eprintln!` panic when the stream cannot be written
//! (`rt2 --help > /dev/full`, `rt2 bench -h | head -1`); these report or absorb the failure.

use rt2::error::{Error, Result};
use std::fmt::Display;
use std::io::{self, Write};

/// Prints `text` and a newline on stdout.
///
/// A closed pipe ends the process quietly with status 0, as ripgrep and others do: the reader
/// (`| head -1`) has what it wanted and the work before this line is done. Any other failure
/// (a full disk) is an error, so a command whose report was lost does not claim success.
pub fn say(text: impl Display) -> Result<()> {
    let mut out = io::stdout().lock();
    match writeln!(out, "{text}").and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => Err(Error::io(format!("cannot write to stdout: {e}"))),
    }
}

/// Prints `text` and a newline on stderr. A failure is ignored: stderr is where failures are
/// reported, so there is nowhere left to report this one.
pub fn warn(text: impl Display) {
    let _ = writeln!(io::stderr(), "{text}");
}
