//! Restart checkpoints: a run stopped by Ctrl-C, a kill or a crash continues from the newest
//! good checkpoint and ends bit-identical to the run in one go.
//!
//! - `format.rs`: the self-describing, checksummed file and its reader;
//! - `layout.rs`: the restart state as one walk of the pool tables (sections, staging size,
//!   the state hash's arrays);
//! - `state.rs`: the header, and restoring a `Simulation` from the layout's sections;
//! - `writer.rs`: the background writer (staging buffer, atomic write, pruning, disk budget);
//! - this file: the `[checkpoint]` settings, picking the checkpoint to resume from, comparing
//!   the scenario it was written with, and `strand inspect`.

pub mod format;
pub mod layout;
pub mod state;
pub mod writer;

pub use format::{Checkpoint, Header};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use crate::config::CheckpointConfig;

/// Folder of a run's checkpoints.
pub fn dir_of(out: &Path) -> PathBuf {
    out.join("checkpoints")
}

/// The newest checkpoint in `dir` that reads back intact, and a line for every problem met on
/// the way (a newest checkpoint that is missing, corrupt or truncated). Corrupt files are
/// renamed `*.corrupt`, kept for inspection but never tried again.
pub fn newest_valid(dir: &Path) -> Result<(Checkpoint, Vec<String>), NoValidCheckpoint> {
    let mut notes = Vec::new();
    let all = writer::list(dir);
    if let Ok(latest) = std::fs::read_to_string(dir.join(writer::LATEST)) {
        let name = latest.trim();
        if !name.is_empty() && !dir.join(name).exists() {
            notes.push(format!("the newest checkpoint written, {name}, is missing (deleted?)"));
        }
    }
    for (_, path) in all.iter().rev() {
        match Checkpoint::open(path) {
            Ok(ck) => return Ok((ck, notes)),
            Err(e) => {
                let aside = path.with_extension("ckpt.corrupt");
                let _ = std::fs::rename(path, &aside);
                notes.push(format!("{e}; set aside as {}", aside.display()));
            }
        }
    }
    Err(NoValidCheckpoint { dir: dir.to_path_buf(), notes })
}

/// No checkpoint in a run's folder reads back intact: the folder, and a line for every problem
/// met on the way.
#[derive(Debug, thiserror::Error)]
#[error("no valid checkpoint in {}{}", dir.display(), notes.iter().map(|n| format!("\n  {n}")).collect::<String>())]
pub struct NoValidCheckpoint {
    pub dir: PathBuf,
    pub notes: Vec<String>,
}

/// Keys whose change does not alter the computed state: they may differ on a resume.
const FREE_KEYS: [&str; 8] =
    ["name", "simulation.threads", "simulation.end_time", "output.vtu", "output.disk_budget", "output.on_disk_full", "memory", "checkpoint"];

fn flatten(prefix: &str, v: &toml::Value, out: &mut BTreeMap<String, String>) {
    match v {
        toml::Value::Table(t) => {
            for (k, x) in t {
                let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                flatten(&key, x, out);
            }
        }
        toml::Value::Array(a) if a.iter().any(|x| x.is_table()) => {
            for (i, x) in a.iter().enumerate() {
                flatten(&format!("{prefix}[{i}]"), x, out);
            }
        }
        other => {
            out.insert(prefix.to_string(), other.to_string());
        }
    }
}

/// A scenario text that is not TOML, `which` saying whose it is (the checkpoint's, or the
/// current one).
#[derive(Debug, thiserror::Error)]
#[error("the {which} scenario does not parse: {source}")]
pub struct ScenarioParseError {
    pub which: &'static str,
    pub source: toml::de::Error,
}

/// `strand inspect` found no checkpoint in a folder.
#[derive(Debug, thiserror::Error)]
#[error("no checkpoints in {}", dir.display())]
pub struct NoCheckpoints {
    pub dir: PathBuf,
}

/// Every key whose value differs between the scenario a checkpoint was written with and the
/// one given now (keys that cannot change the result are left out), one line each.
pub fn scenario_differences(then: &str, now: &str) -> Result<Vec<String>, ScenarioParseError> {
    let parse = |t: &str, which: &'static str| -> Result<BTreeMap<String, String>, ScenarioParseError> {
        let v: toml::Value = toml::from_str(t).map_err(|source| ScenarioParseError { which, source })?;
        let mut m = BTreeMap::new();
        flatten("", &v, &mut m);
        m.retain(|k, _| !FREE_KEYS.iter().any(|f| k == f || k.starts_with(&format!("{f}.")) || k.starts_with(&format!("{f}["))));
        Ok(m)
    };
    let (a, b) = (parse(then, "checkpoint's")?, parse(now, "current")?);
    let mut diffs = Vec::new();
    for k in a.keys().chain(b.keys().filter(|k| !a.contains_key(*k))) {
        let (x, y) = (a.get(k), b.get(k));
        if x != y {
            let show = |v: Option<&String>| v.cloned().unwrap_or_else(|| "(not set)".into());
            diffs.push(format!("{k}: {} in the checkpoint, {} now", show(x), show(y)));
        }
    }
    Ok(diffs)
}

/// `strand inspect`: the header and a summary of a checkpoint (a file, or a run's folder for
/// every checkpoint in it), as text or JSON, and whether every one read back intact.
pub fn inspect(path: &Path, json: bool) -> Result<(String, bool), NoCheckpoints> {
    let files: Vec<PathBuf> = if path.is_dir() {
        let d = if path.join("checkpoints").is_dir() { dir_of(path) } else { path.to_path_buf() };
        let v: Vec<PathBuf> = writer::list(&d).into_iter().map(|(_, p)| p).collect();
        if v.is_empty() {
            return Err(NoCheckpoints { dir: d });
        }
        v
    } else {
        vec![path.to_path_buf()]
    };
    let mut texts = Vec::new();
    let mut values = Vec::new();
    for f in &files {
        let (summary, value) = match Checkpoint::open(f) {
            Ok(ck) => summarise(&ck),
            Err(e) => (format!("{}: INVALID: {e}", f.display()), serde_json::json!({ "path": f, "valid": false, "error": e.to_string() })),
        };
        texts.push(summary);
        values.push(value);
    }
    let valid = values.iter().all(|v| v["valid"] == true);
    if json {
        let v = if values.len() == 1 { values.remove(0) } else { serde_json::Value::Array(values) };
        return Ok((format!("{v:#}"), valid));
    }
    Ok((texts.join("\n\n"), valid))
}

fn summarise(ck: &Checkpoint) -> (String, serde_json::Value) {
    let h = &ck.header;
    let (lo, hi) = bounding_box(ck);
    let memory: Vec<(String, u64)> = h.sections.iter().map(|s| (s.name.clone(), s.bytes)).collect();
    let fmt = crate::memory::fmt_bytes;
    let mut t = format!(
        "{}: valid (format {}, strand {}, {})\n  scenario '{}' (hash {:016x})\n  step {} in progress from t = {:.6} s (dt {:.3e} s, bound {}; grid updated, G2P next)\n  \
         particles {} of {} ({} asleep), {} state values each\n  bounding box [{:.4}, {:.4}, {:.4}] - [{:.4}, {:.4}, {:.4}] m\n  \
         print slabs emitted {}   outputs written {}\n  state hash {:016x}\n  file {}\n  sections:",
        ck.path.display(),
        format::FORMAT,
        h.strand_version,
        h.precision,
        h.scenario_name,
        h.scenario_hash,
        h.step + 1,
        h.time,
        h.dt,
        h.dt_limit,
        h.particles,
        h.capacity,
        h.asleep,
        h.state_len,
        lo[0],
        lo[1],
        lo[2],
        hi[0],
        hi[1],
        hi[2],
        h.emitted_slabs,
        h.outputs,
        h.state_hash,
        fmt(ck.file_len()),
    );
    for (name, b) in &memory {
        t += &format!("\n    {name:<18} {:>12}", fmt(*b));
    }
    let total: u64 = memory.iter().map(|(_, b)| b).sum();
    let per_particle = total as f64 / h.particles.max(1) as f64;
    t += &format!("\n  restart state {per_particle:.1} bytes per particle (every section over the particles)");
    let v = serde_json::json!({
        "path": ck.path,
        "valid": true,
        "format": format::FORMAT,
        "strand_version": h.strand_version,
        "precision": h.precision,
        "scenario": h.scenario_name,
        "scenario_hash": format!("{:016x}", h.scenario_hash),
        "step": h.step,
        "time": h.time,
        "dt": h.dt,
        "dt_limit": h.dt_limit,
        "bytes_per_particle": per_particle,
        "particles": h.particles,
        "capacity": h.capacity,
        "asleep": h.asleep,
        "emitted_slabs": h.emitted_slabs,
        "outputs": h.outputs,
        "bbox_min": lo,
        "bbox_max": hi,
        "state_hash": format!("{:016x}", h.state_hash),
        "file_bytes": ck.file_len(),
        "sections": memory.into_iter().collect::<BTreeMap<_, _>>(),
    });
    (t, v)
}

/// World bounding box of the particles, from the scenario's grid origin and dx.
fn bounding_box(ck: &Checkpoint) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let Ok(sc) = crate::scenario::Scenario::parse(&ck.header.scenario_text) else { return (lo, hi) };
    let geom = crate::grid::GridGeom::new(sc.simulation.dx, sc.domain.min, sc.domain.max, sc.domain.periodic);
    let Some(x) = ck.section(crate::particles::POSITIONS) else { return (lo, hi) };
    let size = std::mem::size_of::<crate::V3>();
    for chunk in x.chunks_exact(size) {
        // the map is page aligned and sections 64-byte aligned, but copy to stay independent
        let v: crate::V3 = bytemuck::pod_read_unaligned(chunk);
        let w = geom.to_world(v);
        for a in 0..3 {
            lo[a] = lo[a].min(w[a]);
            hi[a] = hi[a].max(w[a]);
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn differences_name_keys_and_skip_free_ones() {
        let a = "name='a'\n[simulation]\ndx=0.01\nthreads=1\nend_time=1.0\n[material]\nyield_stress=600.0\n[[body]]\nmin=[0,0,0]\n";
        let b = "name='b'\n[simulation]\ndx=0.01\nthreads=2\nend_time=2.0\ncfl=0.3\n[material]\nyield_stress=630.0\n[[body]]\nmin=[0,0,1]\n";
        let d = scenario_differences(a, b).unwrap();
        assert_eq!(d.len(), 3, "{d:?}");
        assert!(d.iter().any(|l| l.starts_with("material.yield_stress: 600.0 in the checkpoint, 630.0 now")));
        assert!(d.iter().any(|l| l.starts_with("simulation.cfl: (not set)")));
        assert!(d.iter().any(|l| l.starts_with("body[0].min")));
        assert!(scenario_differences(a, a).unwrap().is_empty());
    }
}
