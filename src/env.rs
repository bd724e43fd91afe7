//! The environment variables RT2 reads (`RT2_BACKEND`, `RT2_ADAPTER`, `RT2_GPU_DEVICES`). A
//! variable that is set but cannot be read is an error at context creation, never taken as
//! unset: a typo in a device count would otherwise silently run with the default. An empty
//! value is unset (a shell's `RT2_BACKEND= program` clears a variable that way), for every
//! variable alike.

use crate::error::{Error, Result};
use std::env::VarError;

/// The value of `name`: `None` when unset or empty, an error when set but not UTF-8.
pub(crate) fn var(name: &str) -> Result<Option<String>> {
    match std::env::var(name) {
        Ok(v) if v.is_empty() => Ok(None),
        Ok(v) => Ok(Some(v)),
        Err(VarError::NotPresent) => Ok(None),
        Err(VarError::NotUnicode(v)) => Err(Error::invalid_argument(format!(
            "{name} is not valid UTF-8: {v:?}"
        ))),
    }
}
