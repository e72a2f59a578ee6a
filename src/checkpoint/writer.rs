//! The checkpoint stage of the pipeline: the stepper copies the state into a staging buffer
//! (a memcpy), and the disk writer (`writer.rs`) checksums it, writes it to a temporary file,
//! fsyncs it and renames it into place, then prunes old checkpoints. There is one staging
//! buffer, so the stepper waits only when the previous checkpoint is still being written when
//! the next is due.

use super::format::{checksum, file_size, layout, state_hash, write_to, Header, Section};
use super::layout::Part;
use crate::disk;
use crate::memory::Pool;
use crate::writer::Writer;
use std::io::Write;
use std::path::{Path, PathBuf};

/// File name of the checkpoint at `step`.
pub fn file_name(step: u64) -> String {
    format!("step_{step:012}.ckpt")
}

/// The file naming the newest checkpoint written, so a deleted newest one is noticed.
pub const LATEST: &str = "LATEST";

/// Checkpoints in `dir`, oldest first.
pub fn list(dir: &Path) -> Vec<(u64, PathBuf)> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut v: Vec<(u64, PathBuf)> = rd
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let step = name.strip_prefix("step_")?.strip_suffix(".ckpt")?.parse().ok()?;
            Some((step, e.path()))
        })
        .collect();
    v.sort();
    v
}

/// What the writer reports back.
#[derive(Debug)]
pub enum Event {
    Written { path: PathBuf, step: u64, bytes: u64, state_hash: u64 },
    /// The disk budget has no room for the checkpoint, even with old ones removed.
    NoRoom { step: u64, needed: u64, used: u64, limit: u64 },
    Failed { step: u64, error: std::io::Error },
}

/// Where and how many checkpoints are kept, and the disk budget they share with the outputs.
#[derive(Clone, Debug)]
pub struct Placement {
    pub dir: PathBuf,
    pub keep: usize,
    /// The output folder whose usage counts against `disk_limit`.
    pub out: PathBuf,
    pub disk_limit: Option<u64>,
}

/// A checkpoint copied into the staging buffer but not queued yet: the run keeps the middle of
/// a step that ends on an output, in case the run must stop with a checkpoint after that
/// output (at its end, or when the disk budget refuses the snapshot). It holds the one staging
/// buffer until submitted or released.
pub struct Staged {
    staging: Pool<u8>,
    header: Header,
}

impl Staged {
    pub fn step(&self) -> u64 {
        self.header.step
    }
}

/// Why a checkpoint could not be queued.
#[derive(Debug, thiserror::Error)]
pub enum WriterError {
    /// The writer thread has ended (after a panic).
    #[error("the checkpoint writer has stopped")]
    Stopped,
    #[error("checkpoint staging holds {have} bytes, the state needs {need}")]
    StagingTooSmall { have: usize, need: usize },
}

pub struct CheckpointWriter(Writer<Pool<u8>, Header, Event>);

impl CheckpointWriter {
    pub fn spawn(place: Placement, staging: Pool<u8>) -> std::io::Result<CheckpointWriter> {
        std::fs::create_dir_all(&place.dir)?;
        // temporaries of a run killed while writing
        if let Ok(rd) = std::fs::read_dir(&place.dir) {
            for e in rd.flatten() {
                if e.file_name().to_string_lossy().ends_with(".tmp") {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        let write = move |staging: &Pool<u8>, header: &Header| {
            write_one(&place, staging, header).unwrap_or_else(|error| Event::Failed { step: header.step, error })
        };
        Ok(CheckpointWriter(Writer::spawn("strand-checkpoint", vec![staging], 64, write)?))
    }

    /// Copy `sections` into the staging buffer (waiting for the previous checkpoint to be
    /// written if it is not yet) and queue the checkpoint. `header` is complete but for the
    /// sections, their checksums and the state hash, which the writer fills in.
    pub fn submit(&mut self, header: Header, sections: &[Part]) -> Result<(), WriterError> {
        let staged = self.stage(header, sections)?;
        self.submit_staged(staged)
    }

    /// Copy `sections` into the staging buffer (waiting for it as `submit` does) without
    /// queueing them.
    pub fn stage(&mut self, mut header: Header, sections: &[Part]) -> Result<Staged, WriterError> {
        let mut staging = self.0.buffer().ok_or(WriterError::Stopped)?;
        let lay = layout(sections.iter().map(|p| (p.name.as_str(), p.len)));
        let need = lay.last().map_or(0, |(_, o, b)| (o + b) as usize);
        if need > staging.len() {
            let have = staging.len();
            self.0.give_back(staging);
            return Err(WriterError::StagingTooSmall { have, need });
        }
        let buf = staging.as_mut_slice();
        for ((_, off, len), part) in lay.iter().zip(sections) {
            part.fill(&mut buf[*off as usize..(*off + *len) as usize]);
        }
        header.sections = lay.into_iter().map(|(name, offset, bytes)| Section { name, offset, bytes, xxh3: 0 }).collect();
        Ok(Staged { staging, header })
    }

    /// Queue a staged checkpoint for writing.
    pub fn submit_staged(&mut self, staged: Staged) -> Result<(), WriterError> {
        if !self.0.submit(staged.staging, staged.header) {
            return Err(WriterError::Stopped);
        }
        Ok(())
    }

    /// Drop a staged checkpoint, giving its buffer back.
    pub fn release(&mut self, staged: Staged) {
        self.0.give_back(staged.staging);
    }

    /// An event, if one is ready.
    pub fn poll(&mut self) -> Option<Event> {
        self.0.poll()
    }

    /// Wait until every queued checkpoint is written; their events, oldest first.
    pub fn drain(&mut self) -> Vec<Event> {
        self.0.drain()
    }
}

fn write_one(place: &Placement, staging: &Pool<u8>, header: &Header) -> std::io::Result<Event> {
    let mut header = header.clone();
    let data: Vec<&[u8]> = header
        .sections
        .iter()
        .map(|s| &staging.as_slice()[s.offset as usize..(s.offset + s.bytes) as usize])
        .collect();
    for (s, d) in header.sections.iter_mut().zip(&data) {
        s.xxh3 = checksum(d);
    }
    header.state_hash = state_hash(header.step, header.time, &header.sections);
    let hbytes = postcard::to_allocvec(&header).map_err(|e| std::io::Error::other(e.to_string()))?.len();
    let size = file_size(hbytes, data.iter().map(|d| d.len()));
    let step = header.step;

    if let Some(limit) = place.disk_limit {
        let mut used = disk::usage(&place.out);
        if used + size > limit {
            // make room: checkpoints beyond `keep`, then all but the newest
            let mut old = list(&place.dir);
            old.retain(|(s, _)| *s != step);
            for keep in [place.keep.saturating_sub(1), 1] {
                while old.len() > keep && used + size > limit {
                    let (_, p) = old.remove(0);
                    let _ = std::fs::remove_file(&p);
                    used = disk::usage(&place.out);
                }
            }
            if used + size > limit {
                return Ok(Event::NoRoom { step, needed: size, used, limit });
            }
        }
    }

    let path = place.dir.join(file_name(step));
    let tmp = place.dir.join(format!(".{}.tmp", file_name(step)));
    let result = (|| {
        let f = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::with_capacity(1 << 20, &f);
        write_to(&mut w, &header, &data, disk::fault_check)?;
        w.flush()?;
        drop(w);
        f.sync_all()?;
        std::fs::rename(&tmp, &path)?;
        sync_dir(&place.dir);
        write_latest(&place.dir, &path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    let all = list(&place.dir);
    for (_, p) in all.iter().take(all.len().saturating_sub(place.keep.max(1))) {
        let _ = std::fs::remove_file(p);
    }
    Ok(Event::Written { path, step, bytes: size, state_hash: header.state_hash })
}

fn write_latest(dir: &Path, newest: &Path) -> std::io::Result<()> {
    let tmp = dir.join(".LATEST.tmp");
    let name = newest.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    std::fs::write(&tmp, format!("{name}\n"))?;
    std::fs::rename(&tmp, dir.join(LATEST))?;
    sync_dir(dir);
    Ok(())
}

/// Make a rename durable (best effort: not every filesystem supports syncing a directory).
fn sync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}
