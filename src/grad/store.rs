//! Where the checkpoint schedule keeps its stored states: a fixed number of RAM slots in one
//! mapped pool, and disk slots at fixed offsets of one file, written by the disk writer
//! (`writer.rs`) and read back with positioned reads.
//!
//! Disk writes overlap the forward sweep: `store` hands a copy to the writer and returns; only a
//! `restore` or `free` of a state still in flight waits for it. Two staging buffers circulate
//! between the stepper and the writer, so a third store in a row waits for the first write.

use super::error::{io_err, GradError};
use super::fields::{load, save};
use super::schedule::Tier;
use crate::memory::{Backing, MemoryError, Pool};
use crate::solver::Simulation;
use crate::writer::Writer;
use std::collections::HashMap;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

pub struct RamSlots {
    pool: Pool<u8>,
    bytes: usize,
    /// Step held by each slot.
    held: Vec<Option<u64>>,
}

impl RamSlots {
    pub fn new(slots: usize, bytes: usize, backing: &Backing) -> Result<RamSlots, MemoryError> {
        Ok(RamSlots { pool: Pool::new("grad.ram_slots", slots * bytes, backing)?, bytes, held: vec![None; slots] })
    }

    fn find(&self, step: u64) -> Result<usize, GradError> {
        self.held.iter().position(|h| *h == Some(step)).ok_or(GradError::NoRamCheckpoint(step))
    }

    fn store(&mut self, sim: &Simulation) -> Result<(), GradError> {
        let k = self.held.iter().position(Option::is_none).ok_or(GradError::RamSlotsFull)?;
        save(sim, &mut self.pool.as_mut_slice()[k * self.bytes..(k + 1) * self.bytes]);
        self.held[k] = Some(sim.step);
        Ok(())
    }

    fn restore(&self, sim: &mut Simulation, step: u64) -> Result<(), GradError> {
        let k = self.find(step)?;
        Ok(load(sim, &self.pool.as_slice()[k * self.bytes..(k + 1) * self.bytes])?)
    }

    fn free(&mut self, step: u64) -> Result<(), GradError> {
        let k = self.find(step)?;
        self.held[k] = None;
        Ok(())
    }
}

/// Writes a state (the buffer) at its slot's offset (the job: step, slot), reporting the step.
type SlotWriter = Writer<Vec<u8>, (u64, usize), Result<u64, GradError>>;

/// The disk tier: one file of `slots` fixed-size slots, written at their offsets by the writer
/// thread and read back with positioned reads. A slot is reused in place once its state is
/// freed, so a store costs one positioned write and a free costs nothing: no file is created,
/// mapped or removed per state (that cost dominated the tier when each state had its own file).
///
/// Nothing is synced to the device: the file is the scratch tape of one gradient run, read back
/// by the same process and removed when it ends, so durability buys nothing, and a crash loses
/// the run whatever is on disk. The page cache may therefore hold recently written slots; the
/// RAM cap counts only this process's own buffers (the two staging buffers, which also serve the
/// reads).
pub struct DiskSlots {
    path: PathBuf,
    file: std::fs::File,
    bytes: usize,
    writer: Option<SlotWriter>,
    /// Slot of each stored (or in-flight) step.
    slot_of: HashMap<u64, usize>,
    /// Slots holding nothing, taken from the end.
    free_slots: Vec<usize>,
    in_flight: Vec<u64>,
    /// Bytes written and read, for the report.
    pub written: u64,
    pub read: u64,
}

/// Buffers the disk tier holds in RAM, in stored states: the writer's two staging buffers (a
/// restore reads into one of them).
pub const DISK_TIER_BUFFERS: u64 = 2;

impl DiskSlots {
    /// A tier of `slots` states of `bytes` in a new file in `dir` (named by the process, so two
    /// runs sharing a folder do not meet; an existing file of that name is refused, not
    /// overwritten).
    pub fn new(dir: &Path, bytes: usize, slots: usize) -> Result<DiskSlots, GradError> {
        std::fs::create_dir_all(dir).map_err(io_err("gradient checkpoint folder", dir))?;
        let path = dir.join(format!("grad_states_{}.bin", std::process::id()));
        let file = std::fs::OpenOptions::new().read(true).write(true).create_new(true).open(&path).map_err(io_err("creating", &path))?;
        let out = file.try_clone().map_err(io_err("opening", &path))?;
        let wpath = path.clone();
        let write = move |data: &Vec<u8>, &(step, slot): &(u64, usize)| {
            out.write_all_at(data, (slot * data.len()) as u64).map(|_| step).map_err(io_err("writing", &wpath))
        };
        let writer = Writer::spawn("grad-writer", vec![vec![0u8; bytes]; DISK_TIER_BUFFERS as usize], 4, write).map_err(GradError::WriterStart);
        let writer = match writer {
            Ok(w) => w,
            Err(e) => {
                let _ = std::fs::remove_file(&path);
                return Err(e);
            }
        };
        Ok(DiskSlots {
            path,
            file,
            bytes,
            writer: Some(writer),
            slot_of: HashMap::with_capacity(slots),
            free_slots: (0..slots).rev().collect(),
            in_flight: Vec::new(),
            written: 0,
            read: 0,
        })
    }

    fn settle(&mut self, r: Result<u64, GradError>) -> Result<(), GradError> {
        let step = r?;
        self.in_flight.retain(|&s| s != step);
        self.written += self.bytes as u64;
        Ok(())
    }

    fn writer(&mut self) -> Result<&mut SlotWriter, GradError> {
        self.writer.as_mut().ok_or(GradError::WriterClosed)
    }

    /// Settle the writes that are done.
    fn collect(&mut self) -> Result<(), GradError> {
        while let Some(r) = self.writer()?.poll() {
            self.settle(r)?;
        }
        Ok(())
    }

    /// Wait until `step` (if in flight) is on disk; collect any other finished writes.
    fn wait_for(&mut self, step: u64) -> Result<(), GradError> {
        self.collect()?;
        while self.in_flight.contains(&step) {
            let r = self.writer()?.wait().ok_or(GradError::WriterStopped)?;
            self.settle(r)?;
        }
        Ok(())
    }

    fn slot(&self, step: u64) -> Result<usize, GradError> {
        self.slot_of.get(&step).copied().ok_or(GradError::NoDiskCheckpoint(step))
    }

    fn store(&mut self, sim: &Simulation) -> Result<(), GradError> {
        self.collect()?;
        let slot = self.free_slots.pop().ok_or(GradError::DiskSlotsFull)?;
        let mut data = self.writer()?.buffer().ok_or(GradError::WriterStopped)?;
        save(sim, &mut data);
        self.slot_of.insert(sim.step, slot);
        self.in_flight.push(sim.step);
        if !self.writer()?.submit(data, (sim.step, slot)) {
            return Err(GradError::WriterStopped);
        }
        Ok(())
    }

    fn restore(&mut self, sim: &mut Simulation, step: u64) -> Result<(), GradError> {
        self.wait_for(step)?;
        let slot = self.slot(step)?;
        let mut data = self.writer()?.buffer().ok_or(GradError::WriterStopped)?;
        let got = self.file.read_exact_at(&mut data, (slot * self.bytes) as u64);
        let loaded = match got {
            Ok(()) => load(sim, &data).map_err(GradError::from),
            Err(e) => Err(io_err("reading", &self.path)(e)),
        };
        self.writer()?.give_back(data);
        loaded?;
        self.read += self.bytes as u64;
        Ok(())
    }

    fn free(&mut self, step: u64) -> Result<(), GradError> {
        // the slot is reused only once its write is done
        self.wait_for(step)?;
        let slot = self.slot(step)?;
        self.slot_of.remove(&step);
        self.free_slots.push(slot);
        Ok(())
    }
}

impl Drop for DiskSlots {
    fn drop(&mut self) {
        if let Some(w) = self.writer.take() {
            drop(w.finish());
        }
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Both tiers behind the schedule's Store / Restore / Free actions.
pub struct Store {
    pub ram: RamSlots,
    pub disk: Option<DiskSlots>,
}

impl Store {
    pub fn store(&mut self, sim: &Simulation, tier: Tier) -> Result<(), GradError> {
        match tier {
            Tier::Ram => self.ram.store(sim),
            Tier::Disk => self.disk_mut()?.store(sim),
        }
    }

    pub fn restore(&mut self, sim: &mut Simulation, step: u64, tier: Tier) -> Result<(), GradError> {
        match tier {
            Tier::Ram => self.ram.restore(sim, step),
            Tier::Disk => self.disk_mut()?.restore(sim, step),
        }
    }

    pub fn free(&mut self, step: u64, tier: Tier) -> Result<(), GradError> {
        match tier {
            Tier::Ram => self.ram.free(step),
            Tier::Disk => self.disk_mut()?.free(step),
        }
    }

    fn disk_mut(&mut self) -> Result<&mut DiskSlots, GradError> {
        self.disk.as_mut().ok_or(GradError::NoDiskTier)
    }
}
