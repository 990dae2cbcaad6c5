//! Allocator tuning for programs that use mimalloc as their global allocator (the `btfmrf`
//! binary and the benchmarks). Synthesis allocates and frees many planes of several megabytes;
//! by default mimalloc purges freed memory (gives it back to the kernel) after a delay, and the kernel must then
//! clear every page again on the next allocation (a fifth of a 20-subspace GMRF synthesis).

/// `mi_option_purge_delay` in the mimalloc v3 header that libmimalloc-sys 0.1.49 builds (its
/// Rust bindings do not name it).
const PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// mimalloc's default purge delay, ms (options.c): how the option index is recognised before
/// it is set.
const DEFAULT_PURGE_DELAY: std::ffi::c_long = 1000;

/// Tells mimalloc to keep freed memory committed for reuse (the peak footprint is unchanged;
/// the memory is not given back until exit). Returns false, changing nothing, when the option
/// at the expected index does not hold mimalloc's default (another mimalloc version).
#[allow(unsafe_code)]
pub fn keep_freed_memory() -> bool {
    // SAFETY: mi_option_get and mi_option_set only read and store an integer option; an index
    // that is not a valid option is ignored by mimalloc.
    unsafe {
        if libmimalloc_sys::mi_option_get(PURGE_DELAY) != DEFAULT_PURGE_DELAY {
            return false;
        }
        libmimalloc_sys::mi_option_set(PURGE_DELAY, -1);
    }
    true
}
