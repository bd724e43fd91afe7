//! Reading a subcommand's arguments. They arrive as `OsString`s: on Unix a file name is any
//! bytes, so a model or output path that is not UTF-8 must pass through untouched, while
//! options and their non-path values (numbers, names) are text and must be UTF-8.

use rt2::error::{Error, Result};
use std::ffi::{OsStr, OsString};
use std::path::PathBuf;
use std::str::FromStr;

/// One argument: an option or a positional one (a scene, model path or benchmark name).
pub enum Arg<'a> {
    Flag(&'a str),
    Positional(&'a OsStr),
}

/// Walks the arguments, handing out options, positional arguments and option values.
pub struct Reader<'a> {
    rest: std::slice::Iter<'a, OsString>,
}

impl<'a> Reader<'a> {
    pub fn new(args: &'a [OsString]) -> Self {
        Self { rest: args.iter() }
    }

    /// The next argument; one starting with `-` is an option, so it must be UTF-8 (no option
    /// name is anything else).
    pub fn next_arg(&mut self) -> Option<Result<Arg<'a>>> {
        let arg = self.rest.next()?;
        Some(if arg.as_encoded_bytes().starts_with(b"-") {
            utf8(arg).map(Arg::Flag)
        } else {
            Ok(Arg::Positional(arg))
        })
    }

    /// The value after `flag`, as given: a file path.
    pub fn path(&mut self, flag: &str) -> Result<PathBuf> {
        self.rest
            .next()
            .map(PathBuf::from)
            .ok_or_else(|| Error::invalid_argument(format!("{flag} needs a value")))
    }

    /// The value after `flag` as text (a name or a number).
    pub fn text(&mut self, flag: &str) -> Result<&'a str> {
        let v = self
            .rest
            .next()
            .ok_or_else(|| Error::invalid_argument(format!("{flag} needs a value")))?;
        utf8(v).map_err(|e| Error::invalid_argument(format!("{flag}: {}", e.message)))
    }

    /// The value after `flag`, parsed (a number).
    pub fn parse<T: FromStr>(&mut self, flag: &str) -> Result<T> {
        let v = self.text(flag)?;
        v.parse()
            .map_err(|_| Error::invalid_argument(format!("{flag}: cannot parse '{v}'")))
    }
}

/// Takes `arg` as the command's one positional argument (`what` it is, for the message): a
/// second one is an error, not a silent replacement of the first.
pub fn set_once<'a>(slot: &mut Option<&'a OsStr>, arg: &'a OsStr, what: &str) -> Result<()> {
    if let Some(first) = slot {
        return Err(Error::invalid_argument(format!(
            "unexpected argument '{}': the {what} is already '{}'",
            arg.to_string_lossy(),
            first.to_string_lossy()
        )));
    }
    *slot = Some(arg);
    Ok(())
}

/// `arg` as text, or an error quoting it (its invalid bytes shown as U+FFFD).
pub fn utf8(arg: &OsStr) -> Result<&str> {
    arg.to_str().ok_or_else(|| {
        Error::invalid_argument(format!("'{}' is not valid UTF-8", arg.to_string_lossy()))
    })
}
