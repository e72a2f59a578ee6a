//! The checkpoint file: self-describing, checksummed, written atomically.
//!
//! ```text
//! "STRANDCK"  u32 format  u32 0  u64 header length  u64 xxh3(header)
//! header (postcard)                      padded to 64 bytes
//! section 0 (raw little-endian array)    padded to 64 bytes
//! section 1 ...
//! ```
//!
//! The header lists every section with its offset from the end of the padded header, its
//! length and its xxh3, so any flipped byte or truncation is caught and named. Sections are
//! the pools' bytes as they are in memory (bytemuck), so restoring is a copy.

use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use xxhash_rust::xxh3::xxh3_64;

pub const MAGIC: &[u8; 8] = b"STRANDCK";
/// Bump on any change of the header or of a section's layout or meaning (3: a sleeping block's
/// `sleep.rest` entry is the time it fell asleep, no longer its rest clock; 4: the sleep tables
/// are per 2-cell unit, 8 to a block, and the header counts sleeping units).
pub const FORMAT: u32 = 4;
const PREAMBLE: usize = 8 + 4 + 4 + 8 + 8;
pub const ALIGN: usize = 64;

/// One raw array of the state.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Section {
    pub name: String,
    /// Offset from the start of the data area (after the padded header) [bytes].
    pub offset: u64,
    pub bytes: u64,
    pub xxh3: u64,
}

/// Everything a checkpoint says about itself.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Header {
    pub strand_version: String,
    /// "f64" or "f32": the width of every real in the sections.
    pub precision: String,
    pub scenario_name: String,
    /// xxh3 of `scenario_text`: equal hashes, same scenario.
    pub scenario_hash: u64,
    /// The scenario's TOML text, to name what changed on a resume.
    pub scenario_text: String,
    /// xxh3 of the resolved toolpath (a G-code file's contents are not in the text).
    pub toolpath_hash: u64,
    /// Steps completed and the time: the checkpoint is in the middle of the next step, after
    /// its grid update and before its G2P.
    pub step: u64,
    pub time: f64,
    /// Length of the step in progress and the bound that set it.
    pub dt: f64,
    pub dt_limit: String,
    pub particles: u64,
    pub asleep: u64,
    pub capacity: u64,
    pub state_len: u32,
    /// Grid blocks the last step activated, the first `particle_blocks` of them holding
    /// particles (sleeping needs the last step's binning).
    pub active_blocks: u64,
    pub particle_blocks: u64,
    pub sleeping_units: u64,
    /// Length of the dense block table (the grid's shape).
    pub table_len: u64,
    /// Slabs of the print handed to the stepper so far.
    pub emitted_slabs: u64,
    /// xxh3 of the particles' masses and initial volumes, which are not stored but rebuilt:
    /// restoring checks the rebuilt arrays against these.
    pub mass_xxh3: u64,
    pub vol0_xxh3: u64,
    /// Outputs written so far (the next is number `outputs + 1`), with the run's PVD entries
    /// and observables as JSON.
    pub outputs: u64,
    pub progress_json: String,
    /// Hash of the physical state (every section and the scalars above): two runs agree
    /// bit for bit iff their hashes agree.
    pub state_hash: u64,
    /// Seconds since the Unix epoch when written.
    pub written_unix: u64,
    pub sections: Vec<Section>,
}

#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: not a strand checkpoint (bad magic)")]
    Magic { path: PathBuf },
    #[error("{path}: checkpoint format {found}, this strand reads format {FORMAT}")]
    Version { path: PathBuf, found: u32 },
    #[error("{path}: truncated: {len} bytes, the {what} needs {need}")]
    Truncated { path: PathBuf, len: u64, need: u64, what: String },
    #[error("{path}: header checksum mismatch (corrupted)")]
    HeaderChecksum { path: PathBuf },
    #[error("{path}: header does not decode: {message}")]
    HeaderDecode { path: PathBuf, message: String },
    #[error("{path}: section '{name}' checksum mismatch (corrupted)")]
    SectionChecksum { path: PathBuf, name: String },
}

/// `n` bytes padded to [`ALIGN`].
pub fn pad(n: usize) -> usize {
    n.div_ceil(ALIGN) * ALIGN
}

/// Lay out `sections` (name, bytes) one after the other, each padded: their offsets.
pub fn layout<'a>(names_and_lens: impl Iterator<Item = (&'a str, usize)>) -> Vec<(String, u64, u64)> {
    let mut off = 0usize;
    names_and_lens
        .map(|(name, len)| {
            let s = (name.to_string(), off as u64, len as u64);
            off += pad(len);
            s
        })
        .collect()
}

/// Combine the scalars and section checksums into the state hash.
pub fn state_hash(step: u64, time: f64, sections: &[Section]) -> u64 {
    let mut buf = Vec::with_capacity(16 + sections.len() * 40);
    buf.extend_from_slice(&step.to_le_bytes());
    buf.extend_from_slice(&time.to_bits().to_le_bytes());
    for s in sections {
        buf.extend_from_slice(s.name.as_bytes());
        buf.extend_from_slice(&s.bytes.to_le_bytes());
        buf.extend_from_slice(&s.xxh3.to_le_bytes());
    }
    xxh3_64(&buf)
}

pub fn checksum(bytes: &[u8]) -> u64 {
    xxh3_64(bytes)
}

/// Write `header` and the section bytes `data[k]` (in `header.sections` order) to `w`, calling
/// `check` before each chunk (the disk-full fault hook). Returns the bytes written.
pub fn write_to(
    w: &mut impl Write,
    header: &Header,
    data: &[&[u8]],
    mut check: impl FnMut(u64) -> std::io::Result<()>,
) -> std::io::Result<u64> {
    let hbytes = postcard::to_allocvec(header).map_err(|e| std::io::Error::other(e.to_string()))?;
    let mut pre = Vec::with_capacity(PREAMBLE);
    pre.extend_from_slice(MAGIC);
    pre.extend_from_slice(&FORMAT.to_le_bytes());
    pre.extend_from_slice(&0u32.to_le_bytes());
    pre.extend_from_slice(&(hbytes.len() as u64).to_le_bytes());
    pre.extend_from_slice(&xxh3_64(&hbytes).to_le_bytes());
    let zeros = [0u8; ALIGN];
    let head = PREAMBLE + hbytes.len();
    let mut total = 0u64;
    let mut put = |w: &mut dyn Write, b: &[u8]| -> std::io::Result<()> {
        check(b.len() as u64)?;
        w.write_all(b)?;
        total += b.len() as u64;
        Ok(())
    };
    put(w, &pre)?;
    put(w, &hbytes)?;
    put(w, &zeros[..pad(head) - head])?;
    for (s, d) in header.sections.iter().zip(data) {
        debug_assert_eq!(s.bytes as usize, d.len());
        for chunk in d.chunks(8 << 20) {
            put(w, chunk)?;
        }
        put(w, &zeros[..pad(d.len()) - d.len()])?;
    }
    Ok(total)
}

/// Size of the file `write_to` produces for a header of `header_bytes` (postcard) bytes and
/// sections of the given lengths.
pub fn file_size(header_bytes: usize, section_lens: impl Iterator<Item = usize>) -> u64 {
    (pad(PREAMBLE + header_bytes) + section_lens.map(pad).sum::<usize>()) as u64
}

/// A checkpoint read back through a memory map, every checksum verified.
pub struct Checkpoint {
    pub path: PathBuf,
    pub header: Header,
    map: memmap2::Mmap,
    data_start: usize,
}

impl Checkpoint {
    /// Map `path` and verify the magic, format, header and every section's checksum.
    pub fn open(path: &Path) -> Result<Checkpoint, FormatError> {
        let io = |source| FormatError::Io { path: path.to_path_buf(), source };
        let file = std::fs::File::open(path).map_err(io)?;
        // SAFETY: checkpoints are only ever replaced by rename, never modified in place.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io)?;
        let header = Self::read_header(path, &map)?;
        let hlen = u64::from_le_bytes(map[16..24].try_into().expect("8 bytes")) as usize;
        let data_start = pad(PREAMBLE + hlen);
        let ck = Checkpoint { path: path.to_path_buf(), header, map, data_start };
        for s in &ck.header.sections {
            let end = (ck.data_start as u64).checked_add(s.offset).and_then(|e| e.checked_add(s.bytes)).unwrap_or(u64::MAX);
            if end > ck.map.len() as u64 {
                return Err(FormatError::Truncated {
                    path: path.to_path_buf(),
                    len: ck.map.len() as u64,
                    need: end,
                    what: format!("section '{}'", s.name),
                });
            }
            if xxh3_64(ck.section_bytes(s)) != s.xxh3 {
                return Err(FormatError::SectionChecksum { path: path.to_path_buf(), name: s.name.clone() });
            }
        }
        Ok(ck)
    }

    /// Only the header (verified), for listings.
    pub fn read_header(path: &Path, bytes: &[u8]) -> Result<Header, FormatError> {
        let p = || path.to_path_buf();
        let len = bytes.len() as u64;
        if bytes.len() < PREAMBLE {
            if bytes.len() >= 8 && &bytes[..8] != MAGIC {
                return Err(FormatError::Magic { path: p() });
            }
            return Err(FormatError::Truncated { path: p(), len, need: PREAMBLE as u64, what: "preamble".into() });
        }
        if &bytes[..8] != MAGIC {
            return Err(FormatError::Magic { path: p() });
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if version != FORMAT {
            return Err(FormatError::Version { path: p(), found: version });
        }
        if bytes[12..16] != [0; 4] {
            return Err(FormatError::HeaderDecode { path: p(), message: "reserved preamble bytes are not zero".into() });
        }
        let hlen = u64::from_le_bytes(bytes[16..24].try_into().expect("8 bytes"));
        let hsum = u64::from_le_bytes(bytes[24..32].try_into().expect("8 bytes"));
        // a length no file can have is corruption, not truncation (the sum would wrap around)
        let Some(need) = (PREAMBLE as u64).checked_add(hlen).filter(|n| *n <= isize::MAX as u64) else {
            return Err(FormatError::HeaderDecode { path: p(), message: format!("header length {hlen} is impossible (corrupted)") });
        };
        if need > len {
            return Err(FormatError::Truncated { path: p(), len, need, what: "header".into() });
        }
        let hb = &bytes[PREAMBLE..PREAMBLE + hlen as usize];
        if xxh3_64(hb) != hsum {
            return Err(FormatError::HeaderChecksum { path: p() });
        }
        postcard::from_bytes(hb).map_err(|e| FormatError::HeaderDecode { path: p(), message: e.to_string() })
    }

    pub fn section(&self, name: &str) -> Option<&[u8]> {
        self.header.sections.iter().find(|s| s.name == name).map(|s| self.section_bytes(s))
    }

    fn section_bytes(&self, s: &Section) -> &[u8] {
        let a = self.data_start + s.offset as usize;
        &self.map[a..a + s.bytes as usize]
    }

    pub fn file_len(&self) -> u64 {
        self.map.len() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(data: &[&[u8]]) -> Header {
        let lay = layout([("a", data[0].len()), ("b", data[1].len())].into_iter());
        let sections: Vec<Section> = lay
            .into_iter()
            .zip(data)
            .map(|((name, offset, bytes), d)| Section { name, offset, bytes, xxh3: checksum(d) })
            .collect();
        Header {
            strand_version: "test".into(),
            precision: "f64".into(),
            scenario_name: "s".into(),
            scenario_hash: 1,
            scenario_text: "name = 's'".into(),
            toolpath_hash: 0,
            step: 7,
            time: 0.5,
            dt: 1e-4,
            dt_limit: "wave".into(),
            particles: 3,
            asleep: 0,
            capacity: 3,
            state_len: 0,
            active_blocks: 0,
            particle_blocks: 0,
            sleeping_units: 0,
            table_len: 0,
            emitted_slabs: 0,
            mass_xxh3: 0,
            vol0_xxh3: 0,
            outputs: 1,
            progress_json: "{}".into(),
            state_hash: state_hash(7, 0.5, &sections),
            written_unix: 0,
            sections,
        }
    }

    fn write(dir: &Path) -> (PathBuf, Header, u64) {
        let a: Vec<u8> = (0..100u8).collect();
        let b = vec![7u8; 1000];
        let h = sample(&[&a, &b]);
        let path = dir.join("c.ckpt");
        let mut f = std::fs::File::create(&path).unwrap();
        let n = write_to(&mut f, &h, &[&a, &b], |_| Ok(())).unwrap();
        (path, h, n)
    }

    #[test]
    fn round_trip_and_size() {
        let d = tempfile::tempdir().unwrap();
        let (path, h, n) = write(d.path());
        let ck = Checkpoint::open(&path).unwrap();
        assert_eq!(ck.header, h);
        assert_eq!(ck.section("a").unwrap(), (0..100u8).collect::<Vec<_>>().as_slice());
        assert_eq!(ck.section("b").unwrap(), vec![7u8; 1000].as_slice());
        let hb = postcard::to_allocvec(&h).unwrap().len();
        assert_eq!(file_size(hb, [100, 1000].into_iter()), n);
        assert_eq!(std::fs::metadata(&path).unwrap().len(), n);
    }

    #[test]
    fn every_flipped_byte_is_caught() {
        let d = tempfile::tempdir().unwrap();
        let (path, _, n) = write(d.path());
        let good = std::fs::read(&path).unwrap();
        // padding bytes carry no information; every other byte must be covered
        let hlen = u64::from_le_bytes(good[16..24].try_into().unwrap()) as usize;
        let ds = pad(PREAMBLE + hlen);
        let meaningful: Vec<usize> =
            (0..PREAMBLE + hlen).chain(ds..ds + 100).chain(ds + pad(100)..ds + pad(100) + 1000).collect();
        for &i in meaningful.iter().step_by(7) {
            let mut bad = good.clone();
            bad[i] ^= 0x10;
            std::fs::write(&path, &bad).unwrap();
            assert!(Checkpoint::open(&path).is_err(), "flip at byte {i} of {n} not detected");
        }
    }

    /// Issue 27 finding 10: a header length near 2^64 is named as such, not as a small
    /// truncation (the sum with the preamble's length wrapped around).
    #[test]
    fn a_huge_header_length_is_not_a_small_truncation() {
        let dir = tempfile::tempdir().unwrap();
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&FORMAT.to_le_bytes());
        bytes.extend_from_slice(&[0; 4]);
        for (hlen, says) in [
            (u64::MAX, format!("header length {} is impossible", u64::MAX)),
            (u64::MAX - 10, format!("header length {} is impossible", u64::MAX - 10)),
            (1 << 40, format!("truncated: 96 bytes, the header needs {}", (1u64 << 40) + 32)),
        ] {
            let mut b = bytes.clone();
            b.extend_from_slice(&hlen.to_le_bytes());
            b.extend_from_slice(&[0; 8 + 64]);
            let path = dir.path().join("c.ckpt");
            std::fs::write(&path, &b).unwrap();
            let e = Checkpoint::open(&path).err().expect("accepted").to_string();
            assert!(e.contains(&says), "{hlen}: {e}");
        }
    }

    #[test]
    fn truncation_is_named() {
        let d = tempfile::tempdir().unwrap();
        let (path, _, n) = write(d.path());
        let good = std::fs::read(&path).unwrap();
        for cut in [0usize, 5, 20, 40, n as usize - 64 - 1000] {
            std::fs::write(&path, &good[..cut]).unwrap();
            let e = Checkpoint::open(&path).err().expect("truncated file accepted").to_string();
            assert!(e.contains("truncated") || e.contains("magic"), "{cut}: {e}");
        }
        std::fs::write(&path, b"STRANDCK\x09\0\0\0").unwrap();
        std::fs::write(&path, [&good[..8], &9u32.to_le_bytes(), &good[12..]].concat()).unwrap();
        assert!(Checkpoint::open(&path).err().unwrap().to_string().contains("format 9"));
    }
}
