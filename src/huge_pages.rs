//! Large read-mostly arrays (the kd-tree's nodes and leaf lists, the triangles) on 2 MiB pages.
//!
//! A traversal reads these arrays at random: an incoherent ray touches a few dozen nodes and
//! triangles spread over tens of megabytes (the dragon's nodes, leaf lists and triangles take
//! about 42 MiB), and with 4 KiB pages many of those reads also miss the TLB, whose entries
//! cover a few megabytes. Embree asks Linux for transparent huge pages on its own allocations
//! (`madvise(MADV_HUGEPAGE)`), and gets them on machines whose THP setting is `madvise`, the
//! common default; RT2's vectors, from the global allocator, got none there.
//!
//! [`advise`] asks for them after the arrays are written: `MADV_HUGEPAGE` marks the range so
//! that the kernel's background collapse and later faults use huge pages, and `MADV_COLLAPSE`
//! (Linux 6.1) moves the pages already written now. Both are advice: on an older kernel, with
//! THP switched off, or without free 2 MiB blocks, the calls fail and nothing changes but the
//! speed. Only the 2 MiB-aligned part inside the array is advised, so no other allocation's
//! memory is touched, and arrays under 2 MiB are left alone (advising the whole 2 MiB blocks
//! the bunny's arrays share with other memory measured no faster: 0.98–1.02x).
//! The collapse copies the pages: 40–60 ms for the dragon's 36 MiB, against its 3 s commit.

/// Asks the kernel to back the whole 2 MiB pages inside `data` with huge pages. Contents are
/// unchanged whatever it answers.
pub(crate) fn advise<T>(data: &[T]) {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        const HUGE: usize = 2 << 20;
        let start = (data.as_ptr() as usize).next_multiple_of(HUGE);
        let end = (data.as_ptr() as usize + std::mem::size_of_val(data)) / HUGE * HUGE;
        if end > start {
            let (ptr, len) = (start as *mut libc::c_void, end - start);
            // SAFETY: `[start, end)` lies inside `data`, a live allocation of this process;
            // neither advice changes the contents of memory, only which pages hold them, so
            // the shared borrow stays valid. Failures (EINVAL on kernels without
            // MADV_COLLAPSE, EAGAIN or ENOMEM without free huge pages) leave the pages as
            // they were and are ignored: the advice is only for speed.
            unsafe {
                libc::madvise(ptr, len, libc::MADV_HUGEPAGE);
                libc::madvise(ptr, len, libc::MADV_COLLAPSE);
            }
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    let _ = data;
}

/// Whether the mapping that holds `addr` is marked for huge pages (`hg` in the `VmFlags` of
/// `/proc/self/smaps`), and whether this kernel has transparent huge pages at all.
#[cfg(all(test, target_os = "linux", target_env = "gnu"))]
pub(crate) fn marked(addr: usize) -> (bool, bool) {
    let smaps = std::fs::read_to_string("/proc/self/smaps").expect("/proc/self/smaps");
    // `/proc/meminfo` counts `AnonHugePages` only on kernels built with transparent huge
    // pages (visible in containers, where `/sys/kernel/mm` may not be).
    let meminfo = std::fs::read_to_string("/proc/meminfo").expect("/proc/meminfo");
    let thp = meminfo.lines().any(|l| l.starts_with("AnonHugePages:"));
    let mut inside = false;
    for line in smaps.lines() {
        let range = line
            .split_whitespace()
            .next()
            .and_then(|r| r.split_once('-'));
        let bounds = range.and_then(|(lo, hi)| {
            Some((
                usize::from_str_radix(lo, 16).ok()?,
                usize::from_str_radix(hi, 16).ok()?,
            ))
        });
        if let Some((lo, hi)) = bounds {
            inside = (lo..hi).contains(&addr);
        } else if inside && line.starts_with("VmFlags:") {
            return (line.split_whitespace().any(|f| f == "hg"), thp);
        }
    }
    panic!("no mapping holds {addr:#x}");
}

#[cfg(all(test, target_os = "linux", target_env = "gnu"))]
mod tests {
    use super::{advise, marked};

    /// An array of 64 MiB (past glibc's largest mmap threshold, so it has pages of its own):
    /// after the advice its contents are unchanged, the whole 2 MiB pages inside it are marked
    /// for huge pages where the kernel has them, and its first and last bytes, which share
    /// their 2 MiB blocks with memory outside it, are not.
    #[test]
    fn advice_marks_the_aligned_inside_only_and_keeps_the_contents() {
        const HUGE: usize = 2 << 20;
        let data: Vec<u32> = (0..16u32 << 20)
            .map(|i| i.wrapping_mul(2654435761))
            .collect();
        let first = data.as_ptr() as usize;
        let last = first + std::mem::size_of_val(data.as_slice()) - 1;
        assert!(
            !first.is_multiple_of(HUGE) && !(last + 1).is_multiple_of(HUGE),
            "the test needs an allocation that is not 2 MiB-aligned at either end"
        );
        advise(&data);
        assert!(data
            .iter()
            .enumerate()
            .all(|(i, &x)| x == (i as u32).wrapping_mul(2654435761)));
        let (inner, thp) = marked(first.next_multiple_of(HUGE));
        assert_eq!(inner, thp);
        assert_eq!(marked(last / HUGE * HUGE - 1).0, thp);
        assert!(!marked(first).0, "the first partial block was advised");
        assert!(!marked(last).0, "the last partial block was advised");
    }
}
