//! What wgpu reports about a device outside error scopes: its error handler (which panics by
//! default) and its lost-device callback record here instead, per thread, and every job checks
//! the record ([`super::Device::check`]).

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::ThreadId;

/// What wgpu's callbacks reported about a device since the last [`super::Device::check`].
#[derive(Default)]
pub(super) struct Faults {
    /// Errors, in order, each with the thread it belongs to.
    pub(super) errors: Vec<Fault>,
    /// Why the device was lost; a lost device stays lost.
    pub(super) lost: Option<String>,
}

/// One error wgpu reported outside error scopes.
pub(super) struct Fault {
    /// The thread whose wgpu call failed: wgpu calls the error handler on it, at once (as it
    /// keeps error scopes per thread). Jobs may share a device (a context serves many threads),
    /// and each job makes its calls and its checks on one thread, so a job takes only its own
    /// errors and another job's out-of-memory does not fail it. `None`: a fault injected by a
    /// test, which the next check on any thread takes.
    thread: Option<ThreadId>,
    pub(super) message: String,
    /// An out-of-memory error (the others are often its consequences: a bind group of a buffer
    /// that was never allocated).
    pub(super) out_of_memory: bool,
}

impl Faults {
    /// Installs the device's error handler and lost-device callback, which record into the
    /// returned list instead of panicking (wgpu's default handler).
    pub(super) fn watch(device: &wgpu::Device) -> Arc<Mutex<Faults>> {
        let faults = Arc::new(Mutex::new(Faults::default()));
        let sink = faults.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            lock_faults(&sink).record(e, Some(std::thread::current().id()));
        }));
        // wgpu reports a lost device only here, never to the error handler.
        let sink = faults.clone();
        device.set_device_lost_callback(move |reason, msg| {
            lock_faults(&sink).lost = Some(match reason {
                wgpu::DeviceLostReason::Destroyed => "destroyed".to_string(),
                wgpu::DeviceLostReason::Unknown if msg.is_empty() => "no reason given".into(),
                wgpu::DeviceLostReason::Unknown => msg,
            });
        });
        faults
    }

    /// Records an error wgpu reported on `thread` (`None`: injected by a test).
    pub(super) fn record(&mut self, e: wgpu::Error, thread: Option<ThreadId>) {
        let (message, out_of_memory) = match e {
            // Its Display is only "Out of Memory"; the source says which allocation failed.
            wgpu::Error::OutOfMemory { source } => (source.to_string(), true),
            e => (e.to_string(), false),
        };
        self.errors.push(Fault {
            thread,
            message,
            out_of_memory,
        });
    }

    /// Whether a check on the calling thread takes `f`: its own errors and injected ones.
    pub(super) fn checked_here(f: &Fault) -> bool {
        f.thread.is_none_or(|t| t == std::thread::current().id())
    }

    /// Takes the errors `mine` picks, leaving the rest (other threads').
    pub(super) fn take(&mut self, mine: impl Fn(&Fault) -> bool) -> Vec<Fault> {
        let (taken, kept) = std::mem::take(&mut self.errors)
            .into_iter()
            .partition(|f| mine(f));
        self.errors = kept;
        taken
    }

    /// Drops the calling thread's own errors (not injected ones): a job's, once it is over.
    pub(super) fn drop_thread_errors(&mut self) {
        let me = Some(std::thread::current().id());
        self.errors.retain(|f| f.thread != me);
    }
}

/// A job's hold on its thread's faults ([`super::Device::begin_job`]). Dropped when the job
/// ends, it drops what the job's wgpu calls reported but no check took (a job that failed before
/// its check). A render band runs on a thread of its own, so what such a thread left would
/// otherwise stay in the device's list for good.
pub(crate) struct JobFaults<'a>(pub(super) &'a Mutex<Faults>);

impl Drop for JobFaults<'_> {
    fn drop(&mut self) {
        lock_faults(self.0).drop_thread_errors();
    }
}

/// Locks a device's fault record whatever a panic left in it: the record is only appended to
/// and taken from, and a lost device must stay known as lost, so it is kept as it is.
pub(super) fn lock_faults(faults: &Mutex<Faults>) -> MutexGuard<'_, Faults> {
    faults.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A fault injected by [`super::Device::inject_fault`], as a driver would report it.
#[doc(hidden)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InjectedFault {
    /// An allocation fails: wgpu reports `Error::OutOfMemory` to the device's handler.
    OutOfMemory,
    /// The device is lost: `wgpu::Device::destroy`, after which wgpu calls the lost callback.
    Lost,
}
