//! Growth of vectors that reports a failed allocation instead of aborting the process.
//!
//! Rust aborts when an allocation fails, which from a C library means the host program dies.
//! A commit allocates in proportion to the scene (placed primitives, the kd-tree build's event
//! lists and node arrays, the renumbering), so its allocations go through these calls: a scene
//! too large for the memory the process may have (`ulimit -v`, an address-space limit on a
//! cluster, one allocation larger than the machine) ends the commit with
//! `RT2_STATUS_OUT_OF_MEMORY` and the scene as it was.
//!
//! [`OutOfMemory`] carries nothing, so failing allocates nothing: the message is written by the
//! `From` conversion into [`Error`], once the failing step (the build, say) has dropped its
//! vectors.
//!
//! This helps where the allocator says no: an address-space limit, strict overcommit, a request
//! larger than the machine. Under Linux's default overcommit a process that fills the RAM is
//! more often stopped by the kernel's OOM killer, which no library can answer.

use crate::error::Error;

/// An allocation failed (or a size overflowed `isize`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutOfMemory;

pub type Fallible<T> = std::result::Result<T, OutOfMemory>;

impl From<std::collections::TryReserveError> for OutOfMemory {
    fn from(_: std::collections::TryReserveError) -> Self {
        OutOfMemory
    }
}

impl From<OutOfMemory> for Error {
    fn from(_: OutOfMemory) -> Self {
        Error::out_of_memory(
            "out of memory for the scene's primitives or kd-tree (or its ropes, exact corners or \
             primitive lookup); the scene is as it was",
        )
    }
}

/// Fallible forms of the `Vec` calls the commit uses.
pub trait TryGrow<T> {
    fn try_push(&mut self, x: T) -> Fallible<()>;
    fn try_extend_from_slice(&mut self, s: &[T]) -> Fallible<()>
    where
        T: Clone;
    /// Extends by an iterator, reserving its lower size hint at once.
    fn try_extend(&mut self, items: impl IntoIterator<Item = T>) -> Fallible<()>;
}

impl<T> TryGrow<T> for Vec<T> {
    #[inline(always)]
    fn try_push(&mut self, x: T) -> Fallible<()> {
        // The full check only when the vector is full: pushes are the builder's inner loop.
        if self.len() == self.capacity() {
            self.try_reserve(1)?;
        }
        self.push(x);
        Ok(())
    }

    fn try_extend_from_slice(&mut self, s: &[T]) -> Fallible<()>
    where
        T: Clone,
    {
        self.try_reserve(s.len())?;
        self.extend_from_slice(s);
        Ok(())
    }

    fn try_extend(&mut self, items: impl IntoIterator<Item = T>) -> Fallible<()> {
        let items = items.into_iter();
        self.try_reserve(items.size_hint().0)?;
        for x in items {
            self.try_push(x)?;
        }
        Ok(())
    }
}

/// `Vec::with_capacity`, failing instead of aborting.
pub fn with_capacity<T>(n: usize) -> Fallible<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)?;
    Ok(v)
}

/// `vec![x; n]`, failing instead of aborting.
pub fn filled<T: Clone>(x: T, n: usize) -> Fallible<Vec<T>> {
    let mut v = with_capacity(n)?;
    v.resize(n, x);
    Ok(v)
}

/// `to_vec`, failing instead of aborting.
pub fn copied<T: Copy>(s: &[T]) -> Fallible<Vec<T>> {
    let mut v = Vec::new();
    v.try_extend_from_slice(s)?;
    Ok(v)
}

/// `collect::<Vec<_>>()`, failing instead of aborting.
pub fn collect<T>(items: impl IntoIterator<Item = T>) -> Fallible<Vec<T>> {
    let mut v = Vec::new();
    v.try_extend(items)?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Rt2Status;

    /// A request past `isize::MAX` bytes fails in every call instead of aborting, and leaves the
    /// vector as it was.
    #[test]
    fn impossible_sizes_are_errors() {
        let huge = usize::MAX / 2;
        assert_eq!(with_capacity::<u64>(huge).err(), Some(OutOfMemory));
        assert_eq!(filled(0u64, huge).err(), Some(OutOfMemory));
        let mut v = vec![1u8, 2];
        assert_eq!(v.try_extend(std::iter::repeat_n(0, huge)), Err(OutOfMemory));
        assert_eq!(v, [1, 2]);
        let e: Error = OutOfMemory.into();
        assert_eq!(e.status, Rt2Status::OutOfMemory);
        let mut w = vec![0u8; 4];
        w.try_extend_from_slice(&[5]).unwrap();
        w.try_push(6).unwrap();
        assert_eq!(w, [0, 0, 0, 0, 5, 6]);
        assert_eq!(collect(1..4).unwrap(), [1, 2, 3]);
        assert_eq!(copied(&[4u8, 5]).unwrap(), [4, 5]);
    }
}
