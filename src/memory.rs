//! Fixed memory: every pool the solver uses is sized at start-up, checked against the budget the
//! scenario declares, and mapped once (anonymous memory, or files under `[memory] dir`). Nothing
//! is allocated after that; running out of a pool is an error that names it.

use bytemuck::Pod;
use memmap2::{MmapMut, MmapOptions};
use std::fmt;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum MemoryError {
    #[error("the scenario does not fit its memory budget of {}:\n{table}  total {} > budget {}\n  (raise [memory] budget, or lower resolution / max_particles / max_blocks)", fmt_bytes(*budget), fmt_bytes(*total), fmt_bytes(*budget))]
    OverBudget { budget: u64, total: u64, table: String },
    #[error("cannot map pool '{pool}' ({}): {source}", fmt_bytes(*bytes))]
    Map { pool: String, bytes: u64, source: std::io::Error },
    #[error("pool '{pool}' is full: {needed} entries needed, capacity {capacity} (raise {hint})")]
    PoolFull { pool: &'static str, needed: usize, capacity: usize, hint: &'static str },
    #[error("bad memory size '{0}': use a number with an optional unit B, KiB, MiB, GiB, KB, MB, GB")]
    BadSize(String),
}

pub fn fmt_bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u < UNITS.len() - 1 {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{v:.2} {}", UNITS[u])
    }
}

/// Parse "2 GiB", "512MiB", "1.5 GB", "1000000" into bytes.
pub fn parse_size(s: &str) -> Result<u64, MemoryError> {
    let t = s.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let num: f64 = num.trim().parse().map_err(|_| MemoryError::BadSize(s.to_string()))?;
    let mult: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "kib" | "k" => 1024.0,
        "mib" | "m" => 1024.0 * 1024.0,
        "gib" | "g" => 1024.0 * 1024.0 * 1024.0,
        "tib" | "t" => 1024.0f64.powi(4),
        "kb" => 1e3,
        "mb" => 1e6,
        "gb" => 1e9,
        "tb" => 1e12,
        _ => return Err(MemoryError::BadSize(s.to_string())),
    };
    if !(num >= 0.0) || !num.is_finite() {
        return Err(MemoryError::BadSize(s.to_string()));
    }
    Ok((num * mult) as u64)
}

/// The pools a run will map, named, with their sizes: checked against the budget before anything
/// is mapped so a scenario that cannot fit fails at once with the whole picture.
#[derive(Clone, Debug, Default)]
pub struct MemoryPlan {
    pub pools: Vec<(String, u64)>,
}

impl MemoryPlan {
    pub fn add<T>(&mut self, name: &str, len: usize) {
        self.add_bytes(name, len * std::mem::size_of::<T>());
    }
    pub fn add_bytes(&mut self, name: &str, bytes: usize) {
        self.pools.push((name.to_string(), bytes as u64));
    }
    pub fn total(&self) -> u64 {
        self.pools.iter().map(|p| p.1).sum()
    }
    pub fn check(&self, budget: u64) -> Result<(), MemoryError> {
        let total = self.total();
        if total <= budget {
            return Ok(());
        }
        let mut table = String::new();
        for (name, b) in &self.pools {
            table.push_str(&format!("  {name:<24} {:>12}\n", fmt_bytes(*b)));
        }
        Err(MemoryError::OverBudget { budget, total, table })
    }
}

impl fmt::Display for MemoryPlan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (name, b) in &self.pools {
            writeln!(f, "  {name:<24} {:>12}", fmt_bytes(*b))?;
        }
        write!(f, "  {:<24} {:>12}", "total", fmt_bytes(self.total()))
    }
}

/// Where pools live.
#[derive(Clone, Debug, Default)]
pub struct Backing {
    /// File-backed pools under this directory; anonymous memory when `None`.
    pub dir: Option<PathBuf>,
}

/// A fixed-capacity array of plain data in its own memory map. A pool declared but not mapped
/// yet (`Pool::default()`, see `pools.rs`) is empty.
pub struct Pool<T: Pod> {
    map: Option<MmapMut>,
    len: usize,
    _t: PhantomData<T>,
}

impl<T: Pod> Default for Pool<T> {
    fn default() -> Self {
        Pool { map: None, len: 0, _t: PhantomData }
    }
}

impl<T: Pod> Pool<T> {
    /// Map `len` zeroed elements.
    pub fn new(name: &str, len: usize, backing: &Backing) -> Result<Self, MemoryError> {
        let bytes = (len * std::mem::size_of::<T>()).max(std::mem::size_of::<T>()).max(1);
        let err = |source| MemoryError::Map { pool: name.to_string(), bytes: bytes as u64, source };
        let map = match &backing.dir {
            None => MmapOptions::new().len(bytes).map_anon().map_err(err)?,
            Some(dir) => {
                let path = pool_file(dir, name);
                let file = std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(&path)
                    .map_err(err)?;
                file.set_len(bytes as u64).map_err(err)?;
                // SAFETY: the file was just created and truncated by us; nothing else maps it.
                unsafe { MmapOptions::new().len(bytes).map_mut(&file).map_err(err)? }
            }
        };
        Ok(Pool { map: Some(map), len, _t: PhantomData })
    }

    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    #[inline]
    pub fn as_slice(&self) -> &[T] {
        match &self.map {
            Some(m) => bytemuck::cast_slice(&m[..self.len * std::mem::size_of::<T>()]),
            None => &[],
        }
    }
    #[inline]
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        match &mut self.map {
            Some(m) => bytemuck::cast_slice_mut(&mut m[..self.len * std::mem::size_of::<T>()]),
            None => &mut [],
        }
    }
}

fn pool_file(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{}.pool", name.replace(['/', '.'], "_")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_size("2 GiB").unwrap(), 2 << 30);
        assert_eq!(parse_size("512MiB").unwrap(), 512 << 20);
        assert_eq!(parse_size("1.5 GB").unwrap(), 1_500_000_000);
        assert_eq!(parse_size("1000").unwrap(), 1000);
        assert!(parse_size("lots").is_err());
        assert!(parse_size("3 parsecs").is_err());
        assert!(parse_size("-1 GiB").is_err());
    }

    #[test]
    fn over_budget_lists_every_pool() {
        let mut plan = MemoryPlan::default();
        plan.add::<f64>("particles.x", 1000);
        plan.add::<u32>("grid.table", 10);
        let e = plan.check(100).unwrap_err().to_string();
        assert!(e.contains("particles.x") && e.contains("grid.table") && e.contains("budget"), "{e}");
        assert!(plan.check(1 << 20).is_ok());
    }

    #[test]
    fn file_backed_pool_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let mut p: Pool<f64> = Pool::new("a.b", 100, &Backing { dir: Some(dir.path().into()) }).unwrap();
        p.as_mut_slice()[99] = 3.5;
        assert_eq!(p.as_slice()[99], 3.5);
        assert!(dir.path().join("a_b.pool").exists());
        let q: Pool<u32> = Pool::new("empty", 0, &Backing::default()).unwrap();
        assert!(q.as_slice().is_empty());
    }
}
