//! Reading a recording holds one chunk at a time, not the file and not all its messages: the heap
//! this test binary uses is counted (a counting global allocator) while every message is read.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use softcontact_bag::{AnyMessage, Recording};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Peak heap above what was live before, while `f` runs [bytes].
fn peak_during(f: impl FnOnce()) -> usize {
    let before = LIVE.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    f();
    PEAK.load(Ordering::Relaxed) - before
}

/// Reads every message (decoding each) and returns how many.
fn read_through(path: &std::path::Path) -> (u64, usize) {
    let mut n = 0u64;
    let peak = peak_during(|| {
        let recording = Recording::open(path).unwrap();
        for m in recording.messages() {
            AnyMessage::decode(&m.unwrap()).unwrap().unwrap();
            n += 1;
        }
        assert!(recording.warnings().is_empty());
    });
    (n, peak)
}

#[test]
fn reading_holds_a_chunk_at_a_time_whatever_the_file_size() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small.mcap");
    let large = dir.path().join("large.mcap");
    let written_small = common::write_samples(&small, 4_000).len() as u64;
    let written_large = common::write_samples(&large, 64_000).len() as u64;
    let size = std::fs::metadata(&large).unwrap().len() as usize;
    let (n_small, peak_small) = read_through(&small);
    let (n_large, peak_large) = read_through(&large);
    assert_eq!((n_small, n_large), (written_small, written_large));
    eprintln!(
        "{written_large} messages, {:.1} MB on disk: peak heap {:.2} MB reading it ({:.2} MB for 1/16 of it)",
        size as f64 / 1e6,
        peak_large as f64 / 1e6,
        peak_small as f64 / 1e6
    );
    // The writer's chunks are 1 MiB uncompressed: a chunk compressed, decompressed and its messages
    // copied out stay under 6 MiB (3.4 MB measured), for a file 16 times larger as for the small one.
    assert!(peak_large < 6 << 20, "peak heap {peak_large} B reading a {size} B file");
    assert!(peak_large < size / 2, "peak heap {peak_large} B reading a {size} B file");
    assert!(peak_large < 2 * peak_small.max(1 << 20), "{peak_large} B vs {peak_small} B for 1/16 of the file");
}
