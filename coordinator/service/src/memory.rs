//! How a long-running coordinator gives memory back to the system. glibc keeps freed
//! blocks of its heaps (one per thread that allocated) for the next allocations, and its
//! threshold for serving a block from `mmap` rises with every large block freed: after one
//! campaign on a large record, the record's columns and their encodings would come from the
//! heaps and a coordinator would hold their size (40–90 MB after a 93 MB record) until it
//! exits.

/// Blocks this large or larger are mapped on their own and unmapped when freed.
const MAPPED_FROM: usize = 1 << 20;

/// Serve every block of [`MAPPED_FROM`] bytes or more from its own mapping, freed to the
/// system at once, whatever was freed before (a fixed threshold turns glibc's moving one
/// off). Call once, at the start of a server.
pub fn map_large_blocks() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` sets an allocator parameter; it is thread-safe and any value of
    // M_MMAP_THRESHOLD up to 32 MiB is accepted.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MAPPED_FROM as libc::c_int);
    }
}

/// Give the memory freed so far back to the system: the free pages of every heap.
pub fn return_freed() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` only releases free memory of the allocator; it is thread-safe.
    unsafe {
        libc::malloc_trim(0);
    }
}
