//! Where the checkpoint schedule keeps its stored states: a fixed number of RAM slots in one
//! mapped pool, and disk slots at fixed offsets of one file (`DiskSlots` says why it writes
//! synchronously and never syncs).

use super::error::{io_err, GradError};
use super::fields::{load, save};
use super::schedule::Tier;
use crate::memory::{Backing, MemoryError, Pool};
use crate::solver::Simulation;
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

/// The disk tier: one file of `slots` fixed-size slots, each state written at its slot's offset
/// and read back from it. A slot is reused in place once its state is freed, so a store costs
/// one positioned write and a free costs nothing: no file is created, mapped or removed per state.
///
/// Writes are synchronous and nothing is synced to the device: the file is the scratch tape of
/// one gradient run, read back by the same process and removed when it ends, so durability buys
/// nothing (a crash loses the run whatever is on disk), and a write lands in the page cache at
/// memory speed. Handing each state to a writer thread instead costs two thread wake-ups per
/// state, more than the copy it overlaps (a 64-particle state is 12.5 KiB and a step 30 us).
/// The RAM cap counts this process's own buffer (one state, the staging of writes and reads);
/// the page cache is the kernel's.
pub struct DiskSlots {
    path: PathBuf,
    file: std::fs::File,
    /// One stored state: what is being written or was just read.
    staging: Vec<u8>,
    /// Slot of each stored step.
    slot_of: HashMap<u64, usize>,
    /// Slots holding nothing, taken from the end.
    free_slots: Vec<usize>,
    /// Bytes written and read, for the report.
    pub written: u64,
    pub read: u64,
}

/// Buffers the disk tier holds in RAM, in stored states.
pub const DISK_TIER_BUFFERS: u64 = 1;

impl DiskSlots {
    /// A tier of `slots` states of `bytes` in a new file in `dir` (named by the process and the
    /// tier's number in it, so two runs sharing a folder, or two gradients of one calibration's
    /// threads, do not meet; an existing file of that name is refused, not overwritten).
    pub fn new(dir: &Path, bytes: usize, slots: usize) -> Result<DiskSlots, GradError> {
        std::fs::create_dir_all(dir).map_err(io_err("gradient checkpoint folder", dir))?;
        static TIERS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let tier = TIERS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = dir.join(format!("grad_states_{}_{tier}.bin", std::process::id()));
        let file = std::fs::OpenOptions::new().read(true).write(true).create_new(true).open(&path).map_err(io_err("creating", &path))?;
        Ok(DiskSlots {
            path,
            file,
            staging: vec![0u8; bytes],
            slot_of: HashMap::with_capacity(slots),
            free_slots: (0..slots).rev().collect(),
            written: 0,
            read: 0,
        })
    }

    fn offset(&self, slot: usize) -> u64 {
        (slot * self.staging.len()) as u64
    }

    fn store(&mut self, sim: &Simulation) -> Result<(), GradError> {
        let slot = self.free_slots.pop().ok_or(GradError::DiskSlotsFull)?;
        save(sim, &mut self.staging);
        self.file.write_all_at(&self.staging, self.offset(slot)).map_err(io_err("writing", &self.path))?;
        self.slot_of.insert(sim.step, slot);
        self.written += self.staging.len() as u64;
        Ok(())
    }

    fn restore(&mut self, sim: &mut Simulation, step: u64) -> Result<(), GradError> {
        let slot = *self.slot_of.get(&step).ok_or(GradError::NoDiskCheckpoint(step))?;
        let at = self.offset(slot);
        self.file.read_exact_at(&mut self.staging, at).map_err(io_err("reading", &self.path))?;
        load(sim, &self.staging)?;
        self.read += self.staging.len() as u64;
        Ok(())
    }

    fn free(&mut self, step: u64) -> Result<(), GradError> {
        let slot = self.slot_of.remove(&step).ok_or(GradError::NoDiskCheckpoint(step))?;
        self.free_slots.push(slot);
        Ok(())
    }
}

impl Drop for DiskSlots {
    fn drop(&mut self) {
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
