//! The one error type of the crate. Its status codes are the C API's `rt2_status`.

use std::fmt;

/// Result codes of every fallible C call. Explicit numbers, never reused or renumbered.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rt2Status {
    Ok = 0,
    /// NULL pointer, NaN/inf, out of range, unknown enum value.
    InvalidArgument = 1,
    /// The call is not allowed in the object's state (e.g. render before commit).
    InvalidOperation = 2,
    OutOfMemory = 3,
    /// A file is missing or unreadable.
    Io = 4,
    /// A malformed PLY/OBJ file (the message names file and line or byte offset).
    Parse = 5,
    /// Valid input that this version does not handle.
    Unsupported = 6,
    /// The GPU was asked for and none is usable: no adapter at context creation; for a job on
    /// a context that asked for the GPU, a job beyond a device limit, a lost device, or
    /// (lavapipe only) a job the driver's loop budget cut short. An AUTO context runs such a
    /// job on the CPU instead.
    BackendUnavailable = 7,
    /// A bug in RT2: a panic caught at the C boundary.
    Internal = 8,
}

/// An error with the status a C caller receives and the message `rt2_last_error_message` shows.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    pub status: Rt2Status,
    pub message: String,
}

impl Error {
    pub fn new(status: Rt2Status, message: impl Into<String>) -> Self {
        Error {
            status,
            message: message.into(),
        }
    }

    pub fn invalid_argument(message: impl Into<String>) -> Self {
        Self::new(Rt2Status::InvalidArgument, message)
    }

    pub fn invalid_operation(message: impl Into<String>) -> Self {
        Self::new(Rt2Status::InvalidOperation, message)
    }

    pub fn out_of_memory(message: impl Into<String>) -> Self {
        Self::new(Rt2Status::OutOfMemory, message)
    }

    pub fn io(message: impl Into<String>) -> Self {
        Self::new(Rt2Status::Io, message)
    }

    pub fn parse(message: impl Into<String>) -> Self {
        Self::new(Rt2Status::Parse, message)
    }

    pub fn unsupported(message: impl Into<String>) -> Self {
        Self::new(Rt2Status::Unsupported, message)
    }
}

/// `INVALID_ARGUMENT` naming `name` unless `value` lies in `range` (the option checks).
pub fn check_range<T: PartialOrd + fmt::Display>(
    name: &str,
    value: T,
    range: std::ops::RangeInclusive<T>,
) -> Result<()> {
    if range.contains(&value) {
        return Ok(());
    }
    Err(Error::invalid_argument(format!(
        "{name} is {value} (must be in {}..={})",
        range.start(),
        range.end()
    )))
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}: {}", self.status, self.message)
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;
