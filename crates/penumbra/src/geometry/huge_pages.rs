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
//! [`HugePageArray`] maps fresh 2 MiB-aligned storage of its own, advises
//! it, and only then writes the elements into it. The storage does not
//! come from the global allocator: memory that `malloc` hands back after
//! earlier frees (a scene's loading frees large buffers) has often been
//! touched already, and then keeps its small pages whatever the advice
//! (measured: 0 of the 26 MB of mesh_heavy's leaf packets on huge pages
//! in a Python process, 16 of 26 MB in the CLI). Where the kernel refuses
//! (THP `never`, another OS), the array is an ordinary one.

use std::alloc::{alloc, dealloc, handle_alloc_error, Layout};
use std::mem::MaybeUninit;
use std::ops::{Deref, DerefMut};
use std::ptr::NonNull;

/// Arrays smaller than this stay on ordinary pages (an advised range only
/// gets huge pages for the 2 MiB-aligned blocks it covers).
#[cfg_attr(not(target_os = "linux"), allow(dead_code))]
const HUGE_PAGE: usize = 2 << 20;

/// A fixed-length array of `T`, written when it is made (and rewritten in
/// place when a refit moves its contents).
pub(crate) struct HugePageArray<T: Copy> {
    ptr: NonNull<T>,
    len: usize,
    storage: Storage,
}

/// Where the elements of a [`HugePageArray`] live.
#[derive(Clone, Copy)]
enum Storage {
    /// Nothing allocated (`len` is 0 or `T` is zero-sized).
    Nothing,
    /// From the global allocator, with this layout: small arrays, other
    /// operating systems, or where the kernel refused a mapping.
    Heap(Layout),
    /// A mapping of its own, of this many bytes (a whole number of huge
    /// pages, starting on one), advised for huge pages.
    #[cfg(target_os = "linux")]
    Mapped(usize),
}

// SAFETY: the array owns its elements as a `Vec<T>` does (shared access
// through `&self`, unique access through `&mut self`).
unsafe impl<T: Copy + Send> Send for HugePageArray<T> {}
unsafe impl<T: Copy + Sync> Sync for HugePageArray<T> {}

impl<T: Copy> HugePageArray<T> {
    pub(crate) fn new(items: &[T]) -> HugePageArray<T> {
        let mut array = HugePageArray::with_storage(items.len());
        // SAFETY: the storage holds `items.len()` elements of `T`, and a
        // fresh allocation does not overlap `items`.
        unsafe {
            std::ptr::copy_nonoverlapping(items.as_ptr(), array.ptr.as_ptr(), items.len());
        }
        // `len` counts initialised elements: set once they are written
        array.len = items.len();
        array
    }

    /// The array `[f(0), f(1), …, f(n - 1)]`, its elements computed in
    /// parallel and written straight into the advised storage (no second
    /// copy of a large array alive at once).
    pub(crate) fn from_fn_par(n: usize, f: impl Fn(usize) -> T + Sync) -> HugePageArray<T>
    where
        T: Send,
    {
        use rayon::prelude::*;
        let mut array = HugePageArray::<T>::with_storage(n);
        // SAFETY: the storage holds `n` elements of `T`, not yet
        // initialised, which `MaybeUninit` allows.
        let slots = unsafe {
            std::slice::from_raw_parts_mut(array.ptr.as_ptr().cast::<MaybeUninit<T>>(), n)
        };
        slots
            .par_iter_mut()
            .with_min_len(1024)
            .enumerate()
            .for_each(|(i, slot)| {
                slot.write(f(i));
            });
        // only now that every element is written (if `f` panicked, the
        // array is dropped with `len` 0 and frees its storage)
        array.len = n;
        array
    }

    /// An array of length 0 with storage for `n` elements.
    fn with_storage(n: usize) -> HugePageArray<T> {
        let bytes = n * std::mem::size_of::<T>();
        let mut array = HugePageArray {
            ptr: NonNull::dangling(),
            len: 0,
            storage: Storage::Nothing,
        };
        if bytes == 0 {
            return array;
        }
        let (ptr, storage) = map_huge_pages(bytes).unwrap_or_else(|| {
            let layout =
                Layout::array::<T>(n).expect("an array that fits in memory has a valid layout");
            // SAFETY: `layout` has a non-zero size.
            let raw = unsafe { alloc(layout) };
            let ptr = NonNull::new(raw).unwrap_or_else(|| handle_alloc_error(layout));
            (ptr, Storage::Heap(layout))
        });
        (array.ptr, array.storage) = (ptr.cast::<T>(), storage);
        array
    }
}

/// Fresh, untouched memory for `bytes` (≥ [`HUGE_PAGE`]), aligned to and
/// rounded up to huge pages, advised for them before anything is written;
/// None for smaller arrays or when the kernel refuses the mapping.
#[cfg(target_os = "linux")]
fn map_huge_pages(bytes: usize) -> Option<(NonNull<u8>, Storage)> {
    if bytes < HUGE_PAGE {
        return None;
    }
    let len = bytes.checked_next_multiple_of(HUGE_PAGE)?;
    // a mapping starts on a 4 KiB page: map one huge page more than needed
    // and give back the unaligned head and the tail
    let span = len.checked_add(HUGE_PAGE)?;
    // SAFETY: a new private anonymous mapping; no existing memory is touched.
    let raw = unsafe {
        libc::mmap(
            std::ptr::null_mut(),
            span,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
            -1,
            0,
        )
    };
    if raw == libc::MAP_FAILED {
        return None;
    }
    let start = raw as usize;
    let aligned = start.next_multiple_of(HUGE_PAGE);
    let (head, tail) = (aligned - start, start + span - (aligned + len));
    // SAFETY: both ranges lie in the mapping just made and outside the
    // part kept; the advice changes how the kept part is backed, not its
    // contents (a refusal, THP `never`, leaves small pages: not checked).
    unsafe {
        if head > 0 {
            libc::munmap(raw, head);
        }
        if tail > 0 {
            libc::munmap((aligned + len) as *mut libc::c_void, tail);
        }
        libc::madvise(aligned as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
    }
    Some((NonNull::new(aligned as *mut u8)?, Storage::Mapped(len)))
}

#[cfg(not(target_os = "linux"))]
fn map_huge_pages(_bytes: usize) -> Option<(NonNull<u8>, Storage)> {
    None
}

impl<T: Copy> Drop for HugePageArray<T> {
    fn drop(&mut self) {
        let ptr = self.ptr.as_ptr().cast::<u8>();
        // `T: Copy` has no destructor to run, only the storage to free
        match self.storage {
            Storage::Nothing => {}
            // SAFETY: allocated in `with_storage` with this layout.
            Storage::Heap(layout) => unsafe { dealloc(ptr, layout) },
            // SAFETY: mapped by `map_huge_pages` with this length, and
            // not referenced once the array is gone.
            #[cfg(target_os = "linux")]
            Storage::Mapped(len) => unsafe {
                libc::munmap(ptr.cast(), len);
            },
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

impl<T: Copy> DerefMut for HugePageArray<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        // SAFETY: as for `deref`, and `&mut self` makes the access unique.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.len) }
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
            let b = HugePageArray::from_fn_par(n, |i| v[i]);
            assert_eq!(&*b, &v[..]);
            if cfg!(target_os = "linux") && std::mem::size_of_val(&v[..]) >= HUGE_PAGE {
                assert_eq!(a.as_ptr() as usize % HUGE_PAGE, 0);
            }
        }
        let empty: HugePageArray<[f32; 64]> = HugePageArray::default();
        assert!(empty.is_empty());
    }
}
