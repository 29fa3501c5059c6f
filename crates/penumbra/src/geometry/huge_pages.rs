//! Read-only arrays on memory that Linux may back with 2 MiB pages.
//!
//! Incoherent rays (diffuse bounces) visit the nodes and leaf packets of a
//! large tree in no particular order: with 4 KiB pages, mesh_heavy's tree
//! (~30 MB, ~7,700 pages) is several times what the processor's
//! translation caches cover (2,048 entries of the second-level TLB on Zen 3),
//! so many node and packet loads first wait on a page-table walk. With
//! transparent huge pages in their default `madvise` mode, a range asked
//! for with `madvise(MADV_HUGEPAGE)` *before* its pages are first touched
//! is backed by 2 MiB pages as it is filled (a range touched first keeps
//! its 4 KiB pages until a background thread may merge them, much later).
//! [`HugePageArray`] allocates 2 MiB-aligned storage, advises it, and only
//! then writes the elements into it. Where the kernel refuses (THP `never`,
//! another OS), the array is an ordinary one.

use std::alloc::{alloc, dealloc, handle_alloc_error, Layout};
use std::ops::Deref;
use std::ptr::NonNull;

/// Arrays smaller than this stay on ordinary pages (an advised range only
/// gets huge pages for the 2 MiB-aligned blocks it covers).
const HUGE_PAGE: usize = 2 << 20;

/// A fixed-length array of `T`, written once when it is made and then read.
pub(crate) struct HugePageArray<T: Copy> {
    ptr: NonNull<T>,
    len: usize,
    /// The allocation's layout (None: nothing allocated, `len` is 0 or `T`
    /// is zero-sized).
    layout: Option<Layout>,
}

// SAFETY: the array owns its elements as a `Vec<T>` does, and gives out
// only shared access to them.
unsafe impl<T: Copy + Send> Send for HugePageArray<T> {}
unsafe impl<T: Copy + Sync> Sync for HugePageArray<T> {}

impl<T: Copy> HugePageArray<T> {
    pub(crate) fn new(items: &[T]) -> HugePageArray<T> {
        HugePageArray::from_exact_iter(items.iter().copied())
    }

    /// The array of the items of `iter`, written straight into the
    /// advised storage (no second copy of a large array alive at once).
    pub(crate) fn from_exact_iter(iter: impl ExactSizeIterator<Item = T>) -> HugePageArray<T> {
        let n = iter.len();
        let bytes = n * std::mem::size_of::<T>();
        let mut array = HugePageArray {
            ptr: NonNull::dangling(),
            len: 0,
            layout: None,
        };
        if bytes == 0 {
            array.len = n;
            return array;
        }
        let layout = if bytes >= HUGE_PAGE {
            Layout::from_size_align(bytes.next_multiple_of(HUGE_PAGE), HUGE_PAGE)
        } else {
            Layout::array::<T>(n)
        }
        .expect("an array that fits in memory has a valid layout");
        // SAFETY: `layout` has a non-zero size.
        let raw = unsafe { alloc(layout) };
        let Some(ptr) = NonNull::new(raw.cast::<T>()) else {
            handle_alloc_error(layout)
        };
        if layout.align() == HUGE_PAGE {
            advise_huge_pages(raw, layout.size());
        }
        (array.ptr, array.layout) = (ptr, Some(layout));
        // `len` counts the elements written, so that a panicking iterator
        // leaves an array that frees its storage
        for item in iter.take(n) {
            // SAFETY: the storage holds `n` elements of `T` (its size is at
            // least `bytes`, its alignment at least `T`'s) and `len < n`.
            unsafe { array.ptr.as_ptr().add(array.len).write(item) };
            array.len += 1;
        }
        assert_eq!(
            array.len, n,
            "the iterator yielded fewer items than it said"
        );
        array
    }
}

/// Asks Linux to back `[ptr, ptr + len)` with transparent huge pages; a
/// refusal (THP disabled) leaves ordinary pages, so its result is not
/// checked.
#[cfg(target_os = "linux")]
fn advise_huge_pages(ptr: *mut u8, len: usize) {
    // SAFETY: the range is one allocation of ours; the advice changes how
    // its pages are backed, not their contents.
    unsafe { libc::madvise(ptr.cast(), len, libc::MADV_HUGEPAGE) };
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_ptr: *mut u8, _len: usize) {}

impl<T: Copy> Drop for HugePageArray<T> {
    fn drop(&mut self) {
        if let Some(layout) = self.layout {
            // SAFETY: allocated in `from_exact_iter` with this layout; `T: Copy` has
            // no destructor to run.
            unsafe { dealloc(self.ptr.as_ptr().cast(), layout) };
        }
    }
}

impl<T: Copy> Deref for HugePageArray<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        // SAFETY: `ptr` holds `len` initialised elements (or is dangling
        // with nothing to read).
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Clone for HugePageArray<T> {
    fn clone(&self) -> Self {
        HugePageArray::new(self)
    }
}

impl<T: Copy> Default for HugePageArray<T> {
    fn default() -> Self {
        HugePageArray::new(&[])
    }
}

impl<T: Copy + std::fmt::Debug> std::fmt::Debug for HugePageArray<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<T: Copy> From<Vec<T>> for HugePageArray<T> {
    fn from(v: Vec<T>) -> Self {
        HugePageArray::new(&v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_the_elements_it_was_given() {
        for n in [0usize, 1, 1000, (HUGE_PAGE / 8) + 3] {
            let v: Vec<u64> = (0..n as u64).map(|i| i * 7 + 1).collect();
            let a = HugePageArray::from(v.clone());
            assert_eq!(&*a, &v[..]);
            assert_eq!(&*a.clone(), &v[..]);
            if std::mem::size_of_val(&v[..]) >= HUGE_PAGE {
                assert_eq!(a.as_ptr() as usize % HUGE_PAGE, 0);
            }
        }
        let empty: HugePageArray<[f32; 64]> = HugePageArray::default();
        assert!(empty.is_empty());
    }
}
