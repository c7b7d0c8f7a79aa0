//! Large arrays on huge pages: the joint iteration's constraint dual (75 MB at 768², read and
//! written at scattered pixels of 18 000 small pages, far more than the TLB holds) and the unmixed
//! cube of a frame (73 MB written at once: 18 000 page faults on 4 KiB pages, 36 on 2 MiB).

/// Bytes of a transparent huge page on x86-64 and aarch64 Linux.
const HUGE_PAGE: usize = 2 << 20;

/// A zeroed vector of `len` values whose whole 2 MiB pages the kernel is asked to back with
/// transparent huge pages, before any of them is touched (only a hint: Linux only, and without
/// effect where THP is off).
pub fn zeroed<T: Copy + Default>(len: usize) -> Vec<T> {
    let mut v = vec![T::default(); len];
    advise_huge(&mut v);
    v
}

/// `madvise(MADV_HUGEPAGE)` on the 2 MiB-aligned pages inside `v`. A refused hint leaves the
/// array on small pages, which changes its speed only, so the result is not checked.
#[cfg(target_os = "linux")]
fn advise_huge<T>(v: &mut [T]) {
    let start = v.as_mut_ptr() as usize;
    let end = start + std::mem::size_of_val(v);
    let (lo, hi) = (
        start.next_multiple_of(HUGE_PAGE),
        end / HUGE_PAGE * HUGE_PAGE,
    );
    if hi > lo {
        // SAFETY: [lo, hi) lies inside `v`'s allocation; the advice changes no content.
        unsafe { libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE) };
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge<T>(_: &mut [T]) {}

#[cfg(test)]
mod tests {
    use super::*;

    /// The VmFlags of the mapping of this process that holds `addr` (from /proc/self/smaps).
    #[cfg(target_os = "linux")]
    fn vm_flags(addr: usize) -> String {
        let smaps = std::fs::read_to_string("/proc/self/smaps").unwrap();
        let mut inside = false;
        for line in smaps.lines() {
            if let Some((range, _)) = line.split_once(' ') {
                if let Some((lo, hi)) = range.split_once('-') {
                    if let (Ok(lo), Ok(hi)) =
                        (usize::from_str_radix(lo, 16), usize::from_str_radix(hi, 16))
                    {
                        inside = (lo..hi).contains(&addr);
                        continue;
                    }
                }
            }
            if inside {
                if let Some(flags) = line.strip_prefix("VmFlags:") {
                    return flags.trim().to_string();
                }
            }
        }
        panic!("no mapping holds {addr:#x}")
    }

    #[test]
    fn zeroed_is_zero_of_the_length_asked() {
        for len in [0, 1, 1000, 3 << 20] {
            let v: Vec<f32> = zeroed(len);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|&x| x == 0.0));
        }
        let v: Vec<[f32; 4]> = zeroed(7);
        assert_eq!(v, vec![[0.0; 4]; 7]);
    }

    /// Where the kernel has transparent huge pages, the whole 2 MiB pages of a large array
    /// carry the advice ("hg" in the flags of the mapping that holds them).
    #[cfg(target_os = "linux")]
    #[test]
    fn a_large_array_is_advised_onto_huge_pages() {
        if !std::path::Path::new("/sys/kernel/mm/transparent_hugepage/enabled").exists() {
            return;
        }
        let v: Vec<f32> = zeroed(6 << 20); // 24 MiB: at least 11 whole huge pages inside
        let inner = (v.as_ptr() as usize).next_multiple_of(HUGE_PAGE);
        let flags = vm_flags(inner);
        assert!(flags.split(' ').any(|f| f == "hg"), "VmFlags: {flags}");
    }
}
