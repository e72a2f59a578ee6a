//! Where the checkpoint schedule keeps its stored states: a fixed number of RAM slots in one
//! mapped pool, and disk slots as files written by the disk writer (`writer.rs`) and read back
//! through mmap.
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

/// Writes a state (the buffer) into the slot of its step (the job), reporting the step.
type SlotWriter = Writer<Vec<u8>, u64, Result<u64, GradError>>;

pub struct DiskSlots {
    dir: PathBuf,
    bytes: usize,
    writer: Option<SlotWriter>,
    in_flight: Vec<u64>,
    on_disk: Vec<u64>,
    /// Bytes written and read, for the report.
    pub written: u64,
    pub read: u64,
}

fn slot_path(dir: &Path, step: u64) -> PathBuf {
    dir.join(format!("grad_state_{step:012}.bin"))
}

impl DiskSlots {
    pub fn new(dir: &Path, bytes: usize) -> Result<DiskSlots, GradError> {
        std::fs::create_dir_all(dir).map_err(io_err("gradient checkpoint folder", dir))?;
        let wdir = dir.to_path_buf();
        let write = move |data: &Vec<u8>, &step: &u64| {
            let path = slot_path(&wdir, step);
            std::fs::write(&path, data).map(|_| step).map_err(io_err("writing", &path))
        };
        let writer = Writer::spawn("grad-writer", vec![vec![0u8; bytes]; 2], 4, write).map_err(GradError::WriterStart)?;
        Ok(DiskSlots { dir: dir.to_path_buf(), bytes, writer: Some(writer), in_flight: Vec::new(), on_disk: Vec::new(), written: 0, read: 0 })
    }

    fn settle(&mut self, r: Result<u64, GradError>) -> Result<(), GradError> {
        let step = r?;
        self.in_flight.retain(|&s| s != step);
        self.on_disk.push(step);
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

    fn store(&mut self, sim: &Simulation) -> Result<(), GradError> {
        self.collect()?;
        let mut data = self.writer()?.buffer().ok_or(GradError::WriterStopped)?;
        save(sim, &mut data);
        self.in_flight.push(sim.step);
        if !self.writer()?.submit(data, sim.step) {
            return Err(GradError::WriterStopped);
        }
        Ok(())
    }

    fn restore(&mut self, sim: &mut Simulation, step: u64) -> Result<(), GradError> {
        self.wait_for(step)?;
        let path = slot_path(&self.dir, step);
        let file = std::fs::File::open(&path).map_err(io_err("reading", &path))?;
        // SAFETY: the file is ours, complete (its write was acknowledged) and not modified while
        // mapped.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io_err("mapping", &path))?;
        if map.len() != self.bytes {
            return Err(GradError::SlotSize { path, len: map.len(), expected: self.bytes });
        }
        load(sim, &map)?;
        self.read += self.bytes as u64;
        Ok(())
    }

    fn free(&mut self, step: u64) -> Result<(), GradError> {
        self.wait_for(step)?;
        self.on_disk.retain(|&s| s != step);
        let path = slot_path(&self.dir, step);
        std::fs::remove_file(&path).map_err(io_err("removing", &path))
    }
}

impl Drop for DiskSlots {
    fn drop(&mut self) {
        if let Some(w) = self.writer.take() {
            self.on_disk.extend(w.finish().into_iter().flatten());
        }
        for s in self.on_disk.iter().chain(&self.in_flight) {
            let _ = std::fs::remove_file(slot_path(&self.dir, *s));
        }
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
