//! VTK XML UnstructuredGrid (`.vtu`) output of particle clouds, for ParaView.
//!
//! Each point becomes one `VTK_VERTEX` cell, so the cloud renders (and filters)
//! as a proper unstructured grid. Arrays are stored as binary appended raw data
//! (`<AppendedData encoding="raw">`, `header_type="UInt64"`, little endian):
//! each block is a `u64` byte count followed by the array's bytes, and each
//! `DataArray`'s `offset` is the position of its block counted from the byte
//! after the `_` marker.
//!
//! [`write_pvd`] writes a `.pvd` collection that ties a time series of `.vtu`
//! files together.
//!
//! Plain data only (no crate-internal types), so this module stands alone.

use std::fmt::Write as _;
use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::Path;

/// A flat array of values. Points must be `F64` or `F32`.
#[derive(Clone, Copy, Debug)]
pub enum VtuData<'a> {
    F64(&'a [f64]),
    F32(&'a [f32]),
    U32(&'a [u32]),
}

impl VtuData<'_> {
    /// Number of scalar values.
    pub fn len(&self) -> usize {
        match self {
            VtuData::F64(d) => d.len(),
            VtuData::F32(d) => d.len(),
            VtuData::U32(d) => d.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn vtk_type(&self) -> &'static str {
        match self {
            VtuData::F64(_) => "Float64",
            VtuData::F32(_) => "Float32",
            VtuData::U32(_) => "UInt32",
        }
    }

    fn byte_len(&self) -> u64 {
        match self {
            VtuData::F64(d) => std::mem::size_of_val(*d) as u64,
            VtuData::F32(d) => std::mem::size_of_val(*d) as u64,
            VtuData::U32(d) => std::mem::size_of_val(*d) as u64,
        }
    }

    fn write_le<W: Write>(&self, w: &mut W) -> io::Result<()> {
        match self {
            VtuData::F64(d) => write_le_slice(w, d),
            VtuData::F32(d) => write_le_slice(w, d),
            VtuData::U32(d) => write_le_slice(w, d),
        }
    }
}

/// One per-point array: `components` values per point (1 scalar, 3 vector,
/// 9 tensor, ...), point-major (`data[i * components + c]`).
#[derive(Clone, Copy, Debug)]
pub struct VtuField<'a> {
    pub name: &'a str,
    pub components: usize,
    pub data: VtuData<'a>,
}

/// Number of values per chunk when streaming generated arrays (connectivity,
/// offsets, types).
const CHUNK: usize = 16 * 1024;
/// `VTK_VERTEX`.
const VTK_VERTEX: u8 = 1;

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

/// The XML part of a VTU file, the bytes of its appended data, and whether indices are 64-bit.
fn vtu_layout(points: &VtuData<'_>, fields: &[VtuField<'_>]) -> io::Result<(String, u64, bool)> {
    if let VtuData::U32(_) = points {
        return Err(invalid("vtu points must be F64 or F32, not U32".into()));
    }
    if !points.len().is_multiple_of(3) {
        return Err(invalid(format!(
            "vtu points: length {} is not a multiple of 3 (flat xyz)",
            points.len()
        )));
    }
    let n = points.len() / 3;
    for f in fields {
        if f.components == 0 {
            return Err(invalid(format!("vtu field '{}': components must be at least 1", f.name)));
        }
        let expected = f.components.checked_mul(n);
        if expected != Some(f.data.len()) {
            return Err(invalid(format!(
                "vtu field '{}': {} values, expected {} components x {} points = {}",
                f.name,
                f.data.len(),
                f.components,
                n,
                f.components as u128 * n as u128
            )));
        }
    }

    // connectivity and offsets as Int32 when they fit (half the bytes), else Int64
    let wide = n > i32::MAX as usize;
    let index_size: u64 = if wide { 8 } else { 4 };
    let index_type = if wide { "Int64" } else { "Int32" };

    // appended blocks, in the order of the XML: fields, points, connectivity, offsets, types
    let mut offset: u64 = 0;
    let mut next_offset = |bytes: u64| {
        let o = offset;
        offset += 8 + bytes;
        o
    };

    let mut xml = String::with_capacity(2048 + 160 * fields.len());
    xml.push_str("<?xml version=\"1.0\"?>\n");
    xml.push_str(
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n",
    );
    xml.push_str("  <UnstructuredGrid>\n");
    let _ = writeln!(xml, "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">");
    xml.push_str("      <PointData>\n");
    for f in fields {
        let _ = writeln!(
            xml,
            "        <DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"appended\" offset=\"{}\"/>",
            f.data.vtk_type(),
            xml_escape(f.name),
            f.components,
            next_offset(f.data.byte_len())
        );
    }
    xml.push_str("      </PointData>\n");
    xml.push_str("      <Points>\n");
    let _ = writeln!(
        xml,
        "        <DataArray type=\"{}\" Name=\"Points\" NumberOfComponents=\"3\" format=\"appended\" offset=\"{}\"/>",
        points.vtk_type(),
        next_offset(points.byte_len())
    );
    xml.push_str("      </Points>\n");
    xml.push_str("      <Cells>\n");
    let n64 = n as u64;
    let _ = writeln!(
        xml,
        "        <DataArray type=\"{index_type}\" Name=\"connectivity\" format=\"appended\" offset=\"{}\"/>",
        next_offset(n64 * index_size)
    );
    let _ = writeln!(
        xml,
        "        <DataArray type=\"{index_type}\" Name=\"offsets\" format=\"appended\" offset=\"{}\"/>",
        next_offset(n64 * index_size)
    );
    let _ = writeln!(
        xml,
        "        <DataArray type=\"UInt8\" Name=\"types\" format=\"appended\" offset=\"{}\"/>",
        next_offset(n64)
    );
    xml.push_str("      </Cells>\n");
    xml.push_str("    </Piece>\n");
    xml.push_str("  </UnstructuredGrid>\n");
    xml.push_str("  <AppendedData encoding=\"raw\">\n   _");
    let appended = offset;
    Ok((xml, appended, wide))
}

/// Size in bytes of the file [`write_vtu`] writes for these arguments (for disk budgets).
pub fn vtu_size(points: &VtuData<'_>, fields: &[VtuField<'_>]) -> io::Result<u64> {
    let (xml, appended, _) = vtu_layout(points, fields)?;
    Ok(xml.len() as u64 + appended + VTU_TRAILER.len() as u64)
}

const VTU_TRAILER: &[u8] = b"\n  </AppendedData>\n</VTKFile>\n";

/// Writes a `.vtu` file holding `n = points.len() / 3` points (flat xyz), one
/// vertex cell per point, and the given point fields.
///
/// Writes atomically: the file is written to a temporary file in the same
/// directory, which is then renamed over `path`, so a reader (ParaView
/// watching a series) never sees a partial file. The data is not fsync'ed.
///
/// Errors of kind `InvalidInput`: points not `F64`/`F32` or not a multiple of
/// 3 long, a field with `components == 0`, or a field whose length is not
/// `components * n` (the message names the field).
pub fn write_vtu(path: &Path, points: VtuData<'_>, fields: &[VtuField<'_>]) -> io::Result<()> {
    let (xml, _, wide) = vtu_layout(&points, fields)?;
    let n = points.len() / 3;
    let n64 = n as u64;
    write_atomically(path, |w| {
        w.write_all(xml.as_bytes())?;
        for f in fields {
            w.write_all(&f.data.byte_len().to_le_bytes())?;
            f.data.write_le(w)?;
        }
        w.write_all(&points.byte_len().to_le_bytes())?;
        points.write_le(w)?;
        // connectivity: 0..n; offsets: 1..=n (end of each one-point cell)
        if wide {
            write_index_range::<W64, _>(w, 0, n64)?;
            write_index_range::<W64, _>(w, 1, n64)?;
        } else {
            write_index_range::<W32, _>(w, 0, n64)?;
            write_index_range::<W32, _>(w, 1, n64)?;
        }
        w.write_all(&n64.to_le_bytes())?;
        let types = [VTK_VERTEX; CHUNK];
        let mut left = n;
        while left > 0 {
            let k = left.min(CHUNK);
            w.write_all(&types[..k])?;
            left -= k;
        }
        w.write_all(VTU_TRAILER)
    })
}

/// Writes a ParaView collection (`.pvd`) of a time series: one
/// `<DataSet timestep=... file=...>` per entry, `file` relative to the `.pvd`'s
/// directory. Written atomically like [`write_vtu`]. A non-finite time is an
/// `InvalidInput` error.
pub fn write_pvd(path: &Path, entries: &[(f64, String)]) -> io::Result<()> {
    let mut xml = String::with_capacity(128 + 96 * entries.len());
    xml.push_str("<?xml version=\"1.0\"?>\n");
    xml.push_str("<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
    xml.push_str("  <Collection>\n");
    for (t, file) in entries {
        if !t.is_finite() {
            return Err(invalid(format!("pvd entry '{file}': time {t} is not finite")));
        }
        // `{:?}` is the shortest round-trip form, with an exponent for tiny/huge values
        let _ = writeln!(
            xml,
            "    <DataSet timestep=\"{t:?}\" group=\"\" part=\"0\" file=\"{}\"/>",
            xml_escape(file)
        );
    }
    xml.push_str("  </Collection>\n");
    xml.push_str("</VTKFile>\n");
    write_atomically(path, |w| w.write_all(xml.as_bytes()))
}

/// Creates a temporary file next to `path`, lets `body` fill it through a
/// `BufWriter`, then renames it over `path`. On error the temporary file is
/// removed.
fn write_atomically(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<&fs::File>) -> io::Result<()>,
) -> io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let stem = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let prefix = format!(".{stem}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // a plain output file (umask applies), not tempfile's private 0600
        builder.permissions(fs::Permissions::from_mode(0o644));
    }
    let tmp = builder.tempfile_in(dir)?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file());
        body(&mut w)?;
        w.flush()?;
    }
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Plain-old-data scalars written little endian.
trait LeScalar: bytemuck::Pod {
    fn put_le(self, out: &mut Vec<u8>);
}
impl LeScalar for f64 {
    fn put_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}
impl LeScalar for f32 {
    fn put_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}
impl LeScalar for u32 {
    fn put_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

fn write_le_slice<T: LeScalar, W: Write>(w: &mut W, data: &[T]) -> io::Result<()> {
    if cfg!(target_endian = "little") {
        // in-memory bytes are the file's bytes (large slices bypass the BufWriter's buffer)
        w.write_all(bytemuck::cast_slice(data))
    } else {
        let mut buf = Vec::with_capacity(CHUNK * std::mem::size_of::<T>());
        for chunk in data.chunks(CHUNK) {
            buf.clear();
            for &x in chunk {
                x.put_le(&mut buf);
            }
            w.write_all(&buf)?;
        }
        Ok(())
    }
}

/// Index width of the connectivity and offsets arrays.
trait IndexWidth {
    const BYTES: usize;
    fn put(i: u64, out: &mut [u8]);
}
struct W32;
struct W64;
impl IndexWidth for W32 {
    const BYTES: usize = 4;
    fn put(i: u64, out: &mut [u8]) {
        out.copy_from_slice(&(i as i32).to_le_bytes());
    }
}
impl IndexWidth for W64 {
    const BYTES: usize = 8;
    fn put(i: u64, out: &mut [u8]) {
        out.copy_from_slice(&(i as i64).to_le_bytes());
    }
}

/// Writes one appended block holding `first, first + 1, ..., first + n - 1`,
/// generated in chunks (no array of `n` indices is built).
fn write_index_range<I: IndexWidth, W: Write>(w: &mut W, first: u64, n: u64) -> io::Result<()> {
    w.write_all(&(n * I::BYTES as u64).to_le_bytes())?;
    let mut buf = vec![0u8; CHUNK * I::BYTES];
    let mut i = first;
    let end = first + n;
    while i < end {
        let k = (end - i).min(CHUNK as u64) as usize;
        for (j, slot) in buf[..k * I::BYTES].chunks_exact_mut(I::BYTES).enumerate() {
            I::put(i + j as u64, slot);
        }
        w.write_all(&buf[..k * I::BYTES])?;
        i += k as u64;
    }
    Ok(())
}

fn xml_escape(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.contains(['&', '<', '>', '"', '\'']) {
        return s.into();
    }
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Minimal reader of what `write_vtu` writes: the XML header and the raw blocks.
    struct Parsed {
        xml: String,
        /// bytes after the `_` marker
        appended: Vec<u8>,
    }

    fn parse(path: &Path) -> Parsed {
        let bytes = fs::read(path).unwrap();
        let tag = b"<AppendedData encoding=\"raw\">";
        let at = bytes.windows(tag.len()).position(|w| w == tag).expect("AppendedData tag");
        let underscore = at + bytes[at..].iter().position(|&b| b == b'_').expect("_ marker");
        let xml = String::from_utf8(bytes[..underscore].to_vec()).expect("utf-8 header");
        let tail = b"\n  </AppendedData>\n</VTKFile>\n";
        assert!(bytes.ends_with(tail), "file must end with the closing tags");
        let appended = bytes[underscore + 1..bytes.len() - tail.len()].to_vec();
        Parsed { xml, appended }
    }

    impl Parsed {
        fn attr(line: &str, name: &str) -> Option<String> {
            let key = format!(" {name}=\"");
            let s = line.find(&key)? + key.len();
            let e = s + line[s..].find('"')?;
            Some(line[s..e].to_string())
        }

        /// The `<DataArray>` line with `Name="name"`.
        fn array_line(&self, name: &str) -> &str {
            let key = format!("Name=\"{name}\"");
            self.xml
                .lines()
                .find(|l| l.contains("<DataArray") && l.contains(&key))
                .unwrap_or_else(|| panic!("no DataArray {name}"))
        }

        /// (type, NumberOfComponents, raw block bytes) of an array.
        fn block(&self, name: &str) -> (String, Option<usize>, &[u8]) {
            let line = self.array_line(name);
            assert!(line.contains("format=\"appended\""));
            let ty = Self::attr(line, "type").unwrap();
            let comps = Self::attr(line, "NumberOfComponents").map(|c| c.parse().unwrap());
            let off: usize = Self::attr(line, "offset").unwrap().parse().unwrap();
            let len = u64::from_le_bytes(self.appended[off..off + 8].try_into().unwrap()) as usize;
            (ty, comps, &self.appended[off + 8..off + 8 + len])
        }

        fn number_of_points(&self) -> usize {
            let line = self.xml.lines().find(|l| l.contains("<Piece")).unwrap();
            let n: usize = Self::attr(line, "NumberOfPoints").unwrap().parse().unwrap();
            assert_eq!(Self::attr(line, "NumberOfCells").unwrap().parse::<usize>().unwrap(), n);
            n
        }
    }

    fn f64s(b: &[u8]) -> Vec<f64> {
        b.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
    }
    fn f32s(b: &[u8]) -> Vec<f32> {
        b.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
    }
    fn u32s(b: &[u8]) -> Vec<u32> {
        b.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
    }
    fn i32s(b: &[u8]) -> Vec<i32> {
        b.chunks_exact(4).map(|c| i32::from_le_bytes(c.try_into().unwrap())).collect()
    }

    fn bits64(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }
    fn bits32(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn roundtrip_f64_points_and_fields() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("frame_0001.vtu");
        let n = 5;
        let points: Vec<f64> = (0..3 * n).map(|i| (i as f64) * 0.1 + 1.0 / 3.0).collect();
        let mut vel: Vec<f64> = (0..3 * n).map(|i| -(i as f64).sqrt()).collect();
        vel[4] = -0.0; // bit-exactness includes signed zero
        let pressure: Vec<f32> = (0..n).map(|i| i as f32 * 1.5e-7).collect();
        let ids: Vec<u32> = (0..n as u32).map(|i| i * 7 + 3).collect();
        write_vtu(
            &path,
            VtuData::F64(&points),
            &[
                VtuField { name: "velocity", components: 3, data: VtuData::F64(&vel) },
                VtuField { name: "pressure", components: 1, data: VtuData::F32(&pressure) },
                VtuField { name: "id", components: 1, data: VtuData::U32(&ids) },
            ],
        )
        .unwrap();

        let p = parse(&path);
        assert!(p.xml.starts_with("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\""));
        assert!(p.xml.contains("byte_order=\"LittleEndian\""));
        assert!(p.xml.contains("header_type=\"UInt64\""));
        assert_eq!(p.number_of_points(), n);

        // offsets: blocks are back to back from 0, in XML order
        let offs: Vec<usize> = p
            .xml
            .lines()
            .filter(|l| l.contains("<DataArray"))
            .map(|l| Parsed::attr(l, "offset").unwrap().parse().unwrap())
            .collect();
        let sizes = [3 * n * 8, n * 4, n * 4, 3 * n * 8, n * 4, n * 4, n];
        let mut expect = vec![0usize];
        for s in &sizes[..sizes.len() - 1] {
            expect.push(expect.last().unwrap() + 8 + s);
        }
        assert_eq!(offs, expect);
        assert_eq!(p.appended.len(), expect.last().unwrap() + 8 + n);

        let (ty, comps, raw) = p.block("Points");
        assert_eq!((ty.as_str(), comps), ("Float64", Some(3)));
        assert_eq!(bits64(&f64s(raw)), bits64(&points));
        let (ty, comps, raw) = p.block("velocity");
        assert_eq!((ty.as_str(), comps), ("Float64", Some(3)));
        assert_eq!(bits64(&f64s(raw)), bits64(&vel));
        let (ty, comps, raw) = p.block("pressure");
        assert_eq!((ty.as_str(), comps), ("Float32", Some(1)));
        assert_eq!(bits32(&f32s(raw)), bits32(&pressure));
        let (ty, _, raw) = p.block("id");
        assert_eq!(ty, "UInt32");
        assert_eq!(u32s(raw), ids);

        let (ty, _, raw) = p.block("connectivity");
        assert_eq!(ty, "Int32");
        assert_eq!(i32s(raw), (0..n as i32).collect::<Vec<_>>());
        let (_, _, raw) = p.block("offsets");
        assert_eq!(i32s(raw), (1..=n as i32).collect::<Vec<_>>());
        let (ty, _, raw) = p.block("types");
        assert_eq!(ty, "UInt8");
        assert_eq!(raw, vec![VTK_VERTEX; n].as_slice());

        // only the output file is left in the directory (the temporary was renamed)
        let names: Vec<_> = fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("frame_0001.vtu")]);
    }

    #[test]
    fn roundtrip_f32_points_across_chunks_and_overwrite() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.vtu");
        // first write something else, then overwrite it
        write_vtu(&path, VtuData::F32(&[1.0, 2.0, 3.0]), &[]).unwrap();
        let n = 2 * CHUNK + 123; // exercises the chunked connectivity/offsets/types
        let points: Vec<f32> = (0..3 * n).map(|i| (i as f32).sin()).collect();
        let mass: Vec<f32> = (0..n).map(|i| 1.0 + i as f32 * 1e-3).collect();
        write_vtu(
            &path,
            VtuData::F32(&points),
            &[VtuField { name: "mass", components: 1, data: VtuData::F32(&mass) }],
        )
        .unwrap();
        let p = parse(&path);
        assert_eq!(p.number_of_points(), n);
        let (ty, _, raw) = p.block("Points");
        assert_eq!(ty, "Float32");
        assert_eq!(bits32(&f32s(raw)), bits32(&points));
        let (_, _, raw) = p.block("mass");
        assert_eq!(bits32(&f32s(raw)), bits32(&mass));
        let (_, _, raw) = p.block("connectivity");
        assert_eq!(i32s(raw), (0..n as i32).collect::<Vec<_>>());
        let (_, _, raw) = p.block("offsets");
        assert_eq!(i32s(raw), (1..=n as i32).collect::<Vec<_>>());
        let (_, _, raw) = p.block("types");
        assert!(raw.len() == n && raw.iter().all(|&t| t == VTK_VERTEX));
    }

    #[test]
    fn empty_cloud() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("empty.vtu");
        write_vtu(
            &path,
            VtuData::F64(&[]),
            &[VtuField { name: "v", components: 3, data: VtuData::F64(&[]) }],
        )
        .unwrap();
        let p = parse(&path);
        assert_eq!(p.number_of_points(), 0);
        assert!(p.block("Points").2.is_empty());
        assert!(p.block("types").2.is_empty());
    }

    #[test]
    fn rejects_bad_lengths_naming_the_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.vtu");
        let pts = [0.0f64; 6];
        let e = write_vtu(
            &path,
            VtuData::F64(&pts),
            &[
                VtuField { name: "ok", components: 1, data: VtuData::F64(&[1.0, 2.0]) },
                VtuField { name: "velocity", components: 3, data: VtuData::F64(&[0.0; 5]) },
            ],
        )
        .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("velocity"), "{e}");

        let e = write_vtu(&path, VtuData::F64(&[0.0; 4]), &[]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        let e = write_vtu(&path, VtuData::U32(&[0; 3]), &[]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        let e = write_vtu(
            &path,
            VtuData::F64(&pts),
            &[VtuField { name: "zero", components: 0, data: VtuData::F64(&[]) }],
        )
        .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("zero"), "{e}");
        // nothing written, no temporary left behind
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn field_names_are_escaped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("esc.vtu");
        write_vtu(
            &path,
            VtuData::F64(&[0.0; 3]),
            &[VtuField { name: "a<b>&\"c\"", components: 1, data: VtuData::F64(&[1.0]) }],
        )
        .unwrap();
        let p = parse(&path);
        assert!(p.xml.contains("Name=\"a&lt;b&gt;&amp;&quot;c&quot;\""));
    }

    #[test]
    fn pvd_collection() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("series.pvd");
        write_pvd(
            &path,
            &[(0.0, "frames/f_0000.vtu".to_string()), (0.1, "frames/f_0001.vtu".into()), (1e-7, "x&y.vtu".into())],
        )
        .unwrap();
        let s = fs::read_to_string(&path).unwrap();
        assert!(s.starts_with("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\""));
        let sets: Vec<&str> = s.lines().filter(|l| l.contains("<DataSet")).collect();
        assert_eq!(sets.len(), 3);
        assert!(sets[0].contains("timestep=\"0.0\"") && sets[0].contains("file=\"frames/f_0000.vtu\""));
        assert!(sets[1].contains("timestep=\"0.1\""));
        assert!(sets[2].contains("timestep=\"1e-7\"") && sets[2].contains("file=\"x&amp;y.vtu\""));
        assert!(s.trim_end().ends_with("</VTKFile>"));

        let e = write_pvd(&path, &[(f64::NAN, "a.vtu".into())]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
    }

    #[test]
    fn vtu_size_is_the_written_size() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("s.vtu");
        for n in [0usize, 1, 37] {
            let pts: Vec<f64> = (0..3 * n).map(|i| i as f64).collect();
            let ids: Vec<u32> = (0..n as u32).collect();
            let fields = [VtuField { name: "id", components: 1, data: VtuData::U32(&ids) }];
            write_vtu(&path, VtuData::F64(&pts), &fields).unwrap();
            assert_eq!(vtu_size(&VtuData::F64(&pts), &fields).unwrap(), fs::metadata(&path).unwrap().len());
        }
    }
}
