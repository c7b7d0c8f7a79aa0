//! What depends on the rig alone, kept between runs (`--pattern-cache DIR` or
//! `$SPECMUX_PATTERN_CACHE`): the imaged patterns s̃_k, one file per optical chain, and the
//! simulated calibration captures, one file per rig and camera. Neither depends on the scene, and
//! the full rig takes about a second for each, so a second experiment on the same rig reads them
//! instead — as a lab captures its calibration once, not before every frame. A file holds its
//! whole key and is used only on an exact match; it is written atomically, so a reader never sees
//! half of one.

use specmux_core::error::{Error, Result};
use specmux_core::Cube;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

/// The environment variable naming the cache's folder; unset or empty: no cache.
pub const ENV: &str = "SPECMUX_PATTERN_CACHE";
/// The first line of every cache file.
const MAGIC: &[u8] = b"specmux pattern cache 1\n";

/// What a cache entry holds (a file's extension tells it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Entry {
    /// The imaged patterns of an optical chain (`Chain::cache_key`).
    Patterns,
    /// The calibration captures of a rig and camera (`captures::cache_key`).
    Captures,
}

impl Entry {
    fn extension(self) -> &'static str {
        match self {
            Entry::Patterns => "patterns",
            Entry::Captures => "captures",
        }
    }
}

/// A cache of pattern sets and calibration captures: a folder, or this process's memory.
#[derive(Clone, Debug)]
pub struct PatternCache {
    store: Store,
}

/// Where a cache keeps its cubes.
#[derive(Clone, Debug)]
enum Store {
    /// Files in a folder, kept across processes.
    Folder(PathBuf),
    /// The last cube of each entry, in memory shared by the clones: for the runs of one sweep,
    /// whose rig seldom changes from point to point (one set is held, not one per point). A cube
    /// of more than `limit` bytes is not kept.
    Memory {
        kept: Arc<Mutex<Vec<(Entry, String, Cube)>>>,
        limit: usize,
    },
}

/// The largest cube the memory store keeps, in bytes: 256 MiB, the patterns of the full rig at
/// 2 048² are 100 MB, its captures 134 MB; a larger frame's sets are made again rather than
/// doubling the memory a run needs.
pub const MEMORY_LIMIT_BYTES: usize = 256 << 20;

impl PatternCache {
    /// The cache in `dir`, created if absent; a folder that cannot be made or written is refused
    /// naming it, before any stage runs rather than after the seconds of imaging.
    pub fn open(dir: impl Into<PathBuf>) -> Result<PatternCache> {
        let dir = dir.into();
        let refuse = |what: &str, e: std::io::Error| {
            Error::config(
                "pattern cache",
                ENV,
                dir.display(),
                &format!("{what} ({e})"),
            )
        };
        std::fs::create_dir_all(&dir).map_err(|e| refuse("the folder cannot be created", e))?;
        let probe = dir.join(format!(".probe{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(|e| refuse("the folder cannot be written", e))?;
        let _ = std::fs::remove_file(&probe);
        Ok(PatternCache {
            store: Store::Folder(dir),
        })
    }

    /// A cache in this process's memory that holds the last cube of each entry, up to
    /// [`MEMORY_LIMIT_BYTES`] each.
    pub fn in_memory() -> PatternCache {
        PatternCache::in_memory_up_to(MEMORY_LIMIT_BYTES)
    }

    fn in_memory_up_to(limit: usize) -> PatternCache {
        PatternCache {
            store: Store::Memory {
                kept: Arc::default(),
                limit,
            },
        }
    }

    /// The cache `$SPECMUX_PATTERN_CACHE` names, or None when it is unset or empty.
    pub fn from_env() -> Result<Option<PatternCache>> {
        match std::env::var_os(ENV) {
            Some(d) if !d.is_empty() => PatternCache::open(PathBuf::from(d)).map(Some),
            _ => Ok(None),
        }
    }

    /// Where the `entry` of `key` is kept: its file (named by the key's 64-bit FNV-1a hash in
    /// hex), or the process's memory.
    pub fn place(&self, entry: Entry, key: &str) -> PathBuf {
        match &self.store {
            Store::Folder(dir) => file(dir, entry, key),
            Store::Memory { .. } => PathBuf::from("(this process's memory)"),
        }
    }

    /// Whether something is kept where `key` would be (another key's file, after a hash
    /// collision, counts: `load` tells them apart).
    pub fn holds(&self, entry: Entry, key: &str) -> bool {
        match &self.store {
            Store::Folder(dir) => file(dir, entry, key).exists(),
            Store::Memory { kept, .. } => find(&lock(kept), entry, key).is_some(),
        }
    }

    /// The cube kept under exactly `key`; None if there is none or the file holds another key (a
    /// hash collision). A damaged file is refused naming it.
    pub fn load(&self, entry: Entry, key: &str) -> Result<Option<Cube>> {
        let dir = match &self.store {
            Store::Folder(dir) => dir,
            Store::Memory { kept, .. } => return Ok(find(&lock(kept), entry, key).cloned()),
        };
        let path = file(dir, entry, key);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(Error::io(path, e)),
        };
        decode(&bytes, key).map_err(|why| damaged(&path, why))
    }

    /// Keep `cube` under `key`: in a folder atomically (written beside the file, then renamed),
    /// in memory in place of the entry's last cube.
    pub fn store(&self, entry: Entry, key: &str, cube: &Cube) -> Result<()> {
        match &self.store {
            Store::Folder(dir) => {
                specmux_io::atomic::write_bytes(&file(dir, entry, key), &encode(key, cube))
            }
            Store::Memory { kept, limit } => {
                let mut kept = lock(kept);
                kept.retain(|(e, _, _)| *e != entry);
                if 4 * cube.data.len() <= *limit {
                    kept.push((entry, key.to_string(), cube.clone()));
                }
                Ok(())
            }
        }
    }
}

/// The file of the `entry` of `key` in `dir`.
fn file(dir: &Path, entry: Entry, key: &str) -> PathBuf {
    let hash = fnv1a(key.as_bytes());
    dir.join(format!("{hash:016x}.{}", entry.extension()))
}

/// The cube the memory store keeps for `entry` under exactly `key`.
fn find<'a>(kept: &'a [(Entry, String, Cube)], entry: Entry, key: &str) -> Option<&'a Cube> {
    let entry_of = |(e, k, _): &&(Entry, String, Cube)| (*e, k.as_str()) == (entry, key);
    kept.iter().find(entry_of).map(|(_, _, cube)| cube)
}

/// The memory store's list; a panic elsewhere while it was held leaves it whole (a push or a
/// retain), so a poisoned lock is taken as it is.
fn lock(m: &Mutex<Vec<(Entry, String, Cube)>>) -> MutexGuard<'_, Vec<(Entry, String, Cube)>> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// The one-line refusal of a damaged cache file.
pub(crate) fn damaged(path: &Path, why: impl std::fmt::Display) -> Error {
    Error::io(
        path,
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("damaged pattern-cache file ({why}); delete it and run again"),
        ),
    )
}

/// 64-bit FNV-1a: a stable hash for file names and keys (std's hasher may change between
/// releases).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    fnv1a_from(0xcbf2_9ce4_8422_2325, bytes)
}

/// FNV-1a of the bits of `values` (little-endian): equal iff every value is bit-identical (up to
/// collisions).
pub fn fnv1a_f32(values: &[f32]) -> u64 {
    (values.iter()).fold(fnv1a(b""), |h, v| fnv1a_from(h, &v.to_bits().to_le_bytes()))
}

/// FNV-1a continued from `h` over `bytes`: a long input hashed piece by piece.
fn fnv1a_from(h: u64, bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(h, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// MAGIC, the key's length and bytes, width, height, planes (u64 LE), the values (f32 LE).
fn encode(key: &str, c: &Cube) -> Vec<u8> {
    let mut out = Vec::with_capacity(MAGIC.len() + key.len() + 32 + 4 * c.data.len());
    out.extend_from_slice(MAGIC);
    for n in [key.len(), c.width, c.height, c.planes] {
        out.extend_from_slice(&(n as u64).to_le_bytes());
    }
    out.extend_from_slice(key.as_bytes());
    for v in &c.data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// The cube of a file written by [`encode`] with `key`; Ok(None) for another key, Err(why) for
/// a file [`encode`] did not write whole.
fn decode(bytes: &[u8], key: &str) -> std::result::Result<Option<Cube>, String> {
    let mut r = bytes;
    let mut magic = vec![0u8; MAGIC.len()];
    r.read_exact(&mut magic)
        .map_err(|_| "too short".to_string())?;
    if magic != MAGIC {
        return Err("not a specmux pattern cache of this version".into());
    }
    let mut sizes = [0usize; 4];
    for s in &mut sizes {
        let mut b = [0u8; 8];
        r.read_exact(&mut b)
            .map_err(|_| "header cut short".to_string())?;
        *s = usize::try_from(u64::from_le_bytes(b)).map_err(|_| "size out of range".to_string())?;
    }
    let [key_len, w, h, planes] = sizes;
    let values = w.checked_mul(h).and_then(|n| n.checked_mul(planes));
    let expected = values
        .and_then(|n| n.checked_mul(4))
        .and_then(|n| n.checked_add(key_len));
    if expected != Some(r.len()) {
        return Err(format!(
            "{} bytes after the header, not key + {w}×{h}×{planes} f32",
            r.len()
        ));
    }
    if &r[..key_len] != key.as_bytes() {
        return Ok(None);
    }
    let data: Vec<f32> = r[key_len..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(v) = data.iter().find(|v| !v.is_finite()) {
        return Err(format!("a value is {v}"));
    }
    Cube::from_vec(w, h, planes, data)
        .map(Some)
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> Cube {
        let data = (0..4 * 3 * 2).map(|k| 0.25 * k as f32 - 1.0).collect();
        Cube::from_vec(4, 3, 2, data).unwrap()
    }

    #[test]
    fn a_file_gives_back_its_cube_bit_for_bit_under_its_own_key_only() {
        let c = cube();
        let bytes = encode("chain A", &c);
        let back = decode(&bytes, "chain A").unwrap().unwrap();
        assert_eq!((back.width, back.height, back.planes), (4, 3, 2));
        assert_eq!(back.data, c.data);
        assert!(decode(&bytes, "chain B").unwrap().is_none());
        assert!(decode(&bytes, "chain A ").unwrap().is_none());
    }

    #[test]
    fn a_cut_short_or_foreign_or_non_finite_file_is_damaged_not_a_miss() {
        let c = cube();
        let bytes = encode("k", &c);
        for cut in [0, 10, MAGIC.len() + 5, bytes.len() - 1] {
            let why = decode(&bytes[..cut], "k").unwrap_err();
            assert!(!why.is_empty(), "cut at {cut}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(decode(&longer, "k")
            .unwrap_err()
            .contains("bytes after the header"));
        let mut foreign = bytes.clone();
        foreign[0] = b'S';
        assert!(decode(&foreign, "k").unwrap_err().contains("not a specmux"));
        let mut nan = bytes;
        let at = nan.len() - 4;
        nan[at..].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(decode(&nan, "k").unwrap_err().contains("NaN"));
    }

    #[test]
    fn memory_holds_the_last_cube_of_each_entry_for_every_clone() {
        let m = PatternCache::in_memory();
        let shared = m.clone();
        assert!(m.load(Entry::Patterns, "a").unwrap().is_none());
        m.store(Entry::Patterns, "a", &cube()).unwrap();
        m.store(Entry::Captures, "a", &Cube::zeros(2, 2, 1))
            .unwrap();
        assert!(shared.holds(Entry::Patterns, "a") && shared.holds(Entry::Captures, "a"));
        assert_eq!(
            shared.load(Entry::Patterns, "a").unwrap().unwrap().data,
            cube().data
        );
        assert!(m.load(Entry::Patterns, "b").unwrap().is_none());
        // A second key of an entry takes the first's place; the other entry stays.
        m.store(Entry::Patterns, "b", &Cube::zeros(1, 1, 1))
            .unwrap();
        assert!(!m.holds(Entry::Patterns, "a") && m.holds(Entry::Patterns, "b"));
        assert_eq!(m.load(Entry::Captures, "a").unwrap().unwrap().planes, 1);
        assert_eq!(
            m.place(Entry::Patterns, "b").to_str(),
            Some("(this process's memory)")
        );
    }

    #[test]
    fn memory_keeps_no_cube_over_its_limit_and_drops_the_entry_it_replaces() {
        let m = PatternCache::in_memory_up_to(4 * 24);
        m.store(Entry::Patterns, "a", &cube()).unwrap();
        assert!(m.holds(Entry::Patterns, "a"), "24 values fit 96 bytes");
        m.store(Entry::Patterns, "b", &Cube::zeros(5, 5, 1))
            .unwrap();
        assert!(!m.holds(Entry::Patterns, "b") && !m.holds(Entry::Patterns, "a"));
        assert!(m.load(Entry::Patterns, "b").unwrap().is_none());
    }

    #[test]
    fn fnv1a_matches_its_published_test_vectors() {
        // FNV-1a 64 of "" and "a" (Fowler, Noll & Vo's reference values).
        assert_eq!(fnv1a(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
