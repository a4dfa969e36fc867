//! NPZ archives (NumPy's `np.savez` format) for Python users, and read back
//! as clips.
//!
//! An `.npz` file is a zip archive of `.npy` files, one per array. The `.npy`
//! format is a short text header (a Python dict literal with `descr`,
//! `fortran_order` and `shape`, padded to 64 bytes) followed by the raw
//! little-endian data, so we write it ourselves (about 40 lines) and use the
//! workspace's `zip` crate (deflate) for the archive. `npyz` would do the same
//! job but brings its own zip dependency for what is a dozen lines here.
//!
//! [`NpzWriter`] writes any set of arrays, so other crates add theirs (an
//! occlusion `mask`, say) next to the motion's: [`write_motion`] /
//! [`add_motion`] write
//!
//! | name | dtype | shape | meaning |
//! |---|---|---|---|
//! | `positions` | float32 | `[T, J, 3]` | world joint positions, metres, y up |
//! | `rotations` | float32 | `[T, J, 4]` | local joint rotations, quaternions `(w, x, y, z)` |
//! | `root_translation` | float32 | `[T, 3]` | world root position, metres |
//! | `parents` | int32 | `[J]` | parent joint index, -1 for the root |
//! | `offsets` | float32 | `[J, 3]` | rest offsets from the parent, metres |
//! | `joint_names` | `<U..` | `[J]` | joint names |
//! | `end_sites` | float32 | `[J, 3]` | tip of each leaf joint from the joint, metres, in its frame (NaN for joints without one) |
//! | `fps` | float64 | `[]` | frames per second |
//! | `translations` | float32 | `[T, J, 3]` | only for clips with translation tracks: each joint's local translation (its rest offset where it has no track; the root: its world position) |
//!
//! [`exact_to_bytes`] writes the lossless form the pipeline hands clips on in
//! (`root_translation`, `rotations` and `translations` in float64, `fps`, and
//! the skeleton as JSON in `skeleton_json`, uint8: serde_json round-trips f64
//! exactly with `float_roundtrip`, which the workspace enables).
//!
//! [`read`] reads any archive back (our own and NumPy's uncompressed or
//! deflated ones, for the dtypes above); [`read_motion`] reads a clip from
//! either kind of archive the product writes, so outputs can be fed back in.
//! From the float32 kind the skeleton has what the archive holds (names,
//! parents, offsets, end sites; not the source file's channel layout or static
//! base; lengths in metres); other arrays (an occlusion `mask`) are not part
//! of the clip.

use std::io::{Cursor, Read, Seek, Write};
use std::path::Path;

use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipArchive, ZipWriter};

use glam::{DQuat, DVec3};

use crate::error::{MotionError, ParseError};
use crate::motion::{Motion, Tracks};
use crate::skeleton::{Joint, Skeleton};

/// Element type of an array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DType {
    F32,
    F64,
    I32,
    I64,
    U8,
    Bool,
    /// Fixed-width unicode strings of this many code points (`<U n`).
    Unicode(usize),
}

impl DType {
    fn descr(self) -> String {
        match self {
            DType::F32 => "<f4".into(),
            DType::F64 => "<f8".into(),
            DType::I32 => "<i4".into(),
            DType::I64 => "<i8".into(),
            DType::U8 => "|u1".into(),
            DType::Bool => "|b1".into(),
            DType::Unicode(n) => format!("<U{n}"),
        }
    }

    fn from_descr(d: &str) -> Option<DType> {
        Some(match d {
            "<f4" => DType::F32,
            "<f8" => DType::F64,
            "<i4" => DType::I32,
            "<i8" => DType::I64,
            "|u1" | "<u1" => DType::U8,
            "|b1" => DType::Bool,
            _ => {
                let n = d.strip_prefix("<U")?.parse().ok()?;
                DType::Unicode(n)
            }
        })
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            DType::F32 | DType::I32 => 4,
            DType::F64 | DType::I64 => 8,
            DType::U8 | DType::Bool => 1,
            DType::Unicode(n) => 4 * n,
        }
    }
}

/// One named array: dtype, shape (empty for a scalar) and little-endian data.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    pub name: String,
    pub dtype: DType,
    pub shape: Vec<usize>,
    pub data: Vec<u8>,
}

fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

fn check_len(name: &str, shape: &[usize], len: usize) -> std::io::Result<()> {
    let n: usize = shape.iter().product();
    if n == len {
        Ok(())
    } else {
        Err(invalid(format!(
            "array `{name}`: shape {shape:?} holds {n} values, {len} given"
        )))
    }
}

impl NpyArray {
    pub fn f32(name: &str, shape: &[usize], data: &[f32]) -> std::io::Result<Self> {
        check_len(name, shape, data.len())?;
        Ok(Self::raw(
            name,
            DType::F32,
            shape,
            data.iter().flat_map(|v| v.to_le_bytes()).collect(),
        ))
    }

    pub fn f64(name: &str, shape: &[usize], data: &[f64]) -> std::io::Result<Self> {
        check_len(name, shape, data.len())?;
        Ok(Self::raw(
            name,
            DType::F64,
            shape,
            data.iter().flat_map(|v| v.to_le_bytes()).collect(),
        ))
    }

    pub fn i32(name: &str, shape: &[usize], data: &[i32]) -> std::io::Result<Self> {
        check_len(name, shape, data.len())?;
        Ok(Self::raw(
            name,
            DType::I32,
            shape,
            data.iter().flat_map(|v| v.to_le_bytes()).collect(),
        ))
    }

    pub fn u8(name: &str, shape: &[usize], data: &[u8]) -> std::io::Result<Self> {
        check_len(name, shape, data.len())?;
        Ok(Self::raw(name, DType::U8, shape, data.to_vec()))
    }

    pub fn bool(name: &str, shape: &[usize], data: &[bool]) -> std::io::Result<Self> {
        check_len(name, shape, data.len())?;
        Ok(Self::raw(
            name,
            DType::Bool,
            shape,
            data.iter().map(|&b| b as u8).collect(),
        ))
    }

    /// A unicode string array (`<U n`, n = the longest string in code points).
    pub fn strings<S: AsRef<str>>(
        name: &str,
        shape: &[usize],
        data: &[S],
    ) -> std::io::Result<Self> {
        check_len(name, shape, data.len())?;
        let width = data
            .iter()
            .map(|s| s.as_ref().chars().count())
            .max()
            .unwrap_or(0)
            .max(1);
        let mut bytes = Vec::with_capacity(data.len() * width * 4);
        for s in data {
            let mut n = 0;
            for c in s.as_ref().chars() {
                bytes.extend((c as u32).to_le_bytes());
                n += 1;
            }
            bytes.resize(bytes.len() + (width - n) * 4, 0);
        }
        Ok(Self::raw(name, DType::Unicode(width), shape, bytes))
    }

    fn raw(name: &str, dtype: DType, shape: &[usize], data: Vec<u8>) -> Self {
        NpyArray {
            name: name.to_string(),
            dtype,
            shape: shape.to_vec(),
            data,
        }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn chunks<const N: usize>(&self, dtype: DType) -> Option<impl Iterator<Item = [u8; N]> + '_> {
        (self.dtype == dtype).then(|| {
            self.data
                .chunks_exact(N)
                .map(|c| <[u8; N]>::try_from(c).unwrap_or([0; N]))
        })
    }

    pub fn to_f32(&self) -> Option<Vec<f32>> {
        Some(
            self.chunks::<4>(DType::F32)?
                .map(f32::from_le_bytes)
                .collect(),
        )
    }

    pub fn to_f64(&self) -> Option<Vec<f64>> {
        Some(
            self.chunks::<8>(DType::F64)?
                .map(f64::from_le_bytes)
                .collect(),
        )
    }

    pub fn to_i32(&self) -> Option<Vec<i32>> {
        Some(
            self.chunks::<4>(DType::I32)?
                .map(i32::from_le_bytes)
                .collect(),
        )
    }

    pub fn to_u8(&self) -> Option<Vec<u8>> {
        matches!(self.dtype, DType::U8 | DType::Bool).then(|| self.data.clone())
    }

    pub fn to_strings(&self) -> Option<Vec<String>> {
        let DType::Unicode(width) = self.dtype else {
            return None;
        };
        if width == 0 {
            return Some(vec![String::new(); self.len()]);
        }
        Some(
            self.data
                .chunks_exact(width * 4)
                .map(|item| {
                    item.chunks_exact(4)
                        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                        .take_while(|&u| u != 0)
                        .filter_map(char::from_u32)
                        .collect()
                })
                .collect(),
        )
    }

    /// The `.npy` bytes: header padded to a multiple of 64, then the data.
    fn to_npy(&self) -> Vec<u8> {
        let shape = match self.shape.len() {
            0 => "()".to_string(),
            1 => format!("({},)", self.shape[0]),
            _ => format!(
                "({})",
                self.shape
                    .iter()
                    .map(|s| s.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let mut header = format!(
            "{{'descr': '{}', 'fortran_order': False, 'shape': {shape}, }}",
            self.dtype.descr()
        );
        // magic (6) + version (2) + length (2) + header + '\n' = multiple of 64.
        let unpadded = 10 + header.len() + 1;
        header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
        header.push('\n');
        let mut out = Vec::with_capacity(10 + header.len() + self.data.len());
        out.extend_from_slice(b"\x93NUMPY\x01\x00");
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(&self.data);
        out
    }
}

/// Writes `.npz` archives array by array:
/// `NpzWriter::new(file).array_f32("x", &[2, 3], &xs)?.array_i32(..)?.finish()?`.
pub struct NpzWriter<W: Write + Seek> {
    zip: ZipWriter<W>,
    names: Vec<String>,
}

impl<W: Write + Seek> NpzWriter<W> {
    pub fn new(out: W) -> Self {
        NpzWriter {
            zip: ZipWriter::new(out),
            names: Vec::new(),
        }
    }

    /// Add an array (deflate-compressed `<name>.npy`). Names must be unique.
    pub fn array(mut self, array: &NpyArray) -> std::io::Result<Self> {
        if array.name.is_empty() || self.names.contains(&array.name) {
            return Err(invalid(format!(
                "array name `{}` is empty or already used",
                array.name
            )));
        }
        if array.data.len() != array.len() * array.dtype.size() {
            return Err(invalid(format!(
                "array `{}`: {} data bytes for shape {:?}",
                array.name,
                array.data.len(),
                array.shape
            )));
        }
        let options = SimpleFileOptions::default()
            .compression_method(CompressionMethod::Deflated)
            .large_file(array.data.len() > u32::MAX as usize / 2);
        self.zip
            .start_file(format!("{}.npy", array.name), options)
            .map_err(std::io::Error::other)?;
        self.zip.write_all(&array.to_npy())?;
        self.names.push(array.name.clone());
        Ok(self)
    }

    pub fn array_f32(self, name: &str, shape: &[usize], data: &[f32]) -> std::io::Result<Self> {
        self.array(&NpyArray::f32(name, shape, data)?)
    }

    pub fn array_f64(self, name: &str, shape: &[usize], data: &[f64]) -> std::io::Result<Self> {
        self.array(&NpyArray::f64(name, shape, data)?)
    }

    pub fn array_i32(self, name: &str, shape: &[usize], data: &[i32]) -> std::io::Result<Self> {
        self.array(&NpyArray::i32(name, shape, data)?)
    }

    pub fn array_u8(self, name: &str, shape: &[usize], data: &[u8]) -> std::io::Result<Self> {
        self.array(&NpyArray::u8(name, shape, data)?)
    }

    pub fn array_bool(self, name: &str, shape: &[usize], data: &[bool]) -> std::io::Result<Self> {
        self.array(&NpyArray::bool(name, shape, data)?)
    }

    pub fn array_str<S: AsRef<str>>(
        self,
        name: &str,
        shape: &[usize],
        data: &[S],
    ) -> std::io::Result<Self> {
        self.array(&NpyArray::strings(name, shape, data)?)
    }

    /// A 0-d float64 array (`np.load(f)["fps"]` -> `array(120.)`).
    pub fn scalar_f64(self, name: &str, value: f64) -> std::io::Result<Self> {
        self.array(&NpyArray::f64(name, &[], &[value])?)
    }

    /// Write the zip directory and return the output.
    pub fn finish(self) -> std::io::Result<W> {
        self.zip.finish().map_err(std::io::Error::other)
    }
}

/// Add the standard motion arrays (see the module doc) to `writer`.
pub fn add_motion<W: Write + Seek>(
    writer: NpzWriter<W>,
    motion: &Motion,
) -> std::io::Result<NpzWriter<W>> {
    let (t, j) = (motion.frames(), motion.joints());
    let skeleton = motion.skeleton();
    let positions: Vec<f32> = motion
        .all_world_positions()
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let rotations: Vec<f32> = motion
        .rotations()
        .iter()
        .flat_map(|q| [q.w as f32, q.x as f32, q.y as f32, q.z as f32])
        .collect();
    let root: Vec<f32> = motion
        .root_translation()
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let parents: Vec<i32> = skeleton
        .joints()
        .iter()
        .map(|jt| jt.parent.map_or(-1, |p| p as i32))
        .collect();
    let offsets: Vec<f32> = skeleton
        .joints()
        .iter()
        .flat_map(|jt| [jt.offset.x as f32, jt.offset.y as f32, jt.offset.z as f32])
        .collect();
    let names: Vec<&str> = skeleton
        .joints()
        .iter()
        .map(|jt| jt.name.as_str())
        .collect();
    let end_sites: Vec<f32> = skeleton
        .joints()
        .iter()
        .flat_map(|jt| {
            jt.end_site
                .map_or([f32::NAN; 3], |e| [e.x as f32, e.y as f32, e.z as f32])
        })
        .collect();
    let writer = writer
        .array_f32("positions", &[t, j, 3], &positions)?
        .array_f32("rotations", &[t, j, 4], &rotations)?
        .array_f32("root_translation", &[t, 3], &root)?
        .array_i32("parents", &[j], &parents)?
        .array_f32("offsets", &[j, 3], &offsets)?
        .array_str("joint_names", &[j], &names)?
        .array_f32("end_sites", &[j, 3], &end_sites)?
        .scalar_f64("fps", motion.fps())?;
    if !motion.has_tracks() {
        return Ok(writer);
    }
    let translations: Vec<f32> = translation_rows(motion)
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    writer.array_f32("translations", &[t, j, 3], &translations)
}

/// Every joint's local translation per frame, `[frame][joint]` (the root: its
/// world position), as the `translations` arrays hold them.
fn translation_rows(motion: &Motion) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(motion.frames() * motion.joints());
    for f in 0..motion.frames() {
        out.push(motion.root_translation()[f]);
        out.extend((1..motion.joints()).map(|j| motion.local_translation(f, j)));
    }
    out
}

/// The `.npz` bytes of `motion` plus `extras` (e.g. an occlusion mask).
pub fn motion_to_bytes(motion: &Motion, extras: &[NpyArray]) -> std::io::Result<Vec<u8>> {
    let mut w = add_motion(NpzWriter::new(Cursor::new(Vec::new())), motion)?;
    for e in extras {
        w = w.array(e)?;
    }
    Ok(w.finish()?.into_inner())
}

/// Write `motion` plus `extras` to an `.npz` file.
pub fn write_motion(
    motion: &Motion,
    extras: &[NpyArray],
    path: impl AsRef<Path>,
) -> Result<(), MotionError> {
    let path = path.as_ref();
    let io = |source| MotionError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = motion_to_bytes(motion, extras).map_err(io)?;
    std::fs::write(path, bytes).map_err(io)
}

/// The lossless `.npz` bytes of `motion` (see the module doc) plus `extras`.
pub fn exact_to_bytes(motion: &Motion, extras: &[NpyArray]) -> std::io::Result<Vec<u8>> {
    let (t, j) = (motion.frames(), motion.joints());
    let root: Vec<f64> = motion
        .root_translation()
        .iter()
        .flat_map(|p| [p.x, p.y, p.z])
        .collect();
    let rot: Vec<f64> = motion
        .rotations()
        .iter()
        .flat_map(|q| [q.w, q.x, q.y, q.z])
        .collect();
    let skeleton = serde_json::to_vec(motion.skeleton().as_ref()).map_err(std::io::Error::other)?;
    let mut w = NpzWriter::new(Cursor::new(Vec::new()))
        .array_f64("root_translation", &[t, 3], &root)?
        .array_f64("rotations", &[t, j, 4], &rot)?
        .scalar_f64("fps", motion.fps())?
        .array_u8("skeleton_json", &[skeleton.len()], &skeleton)?;
    if motion.has_tracks() {
        let rows: Vec<f64> = translation_rows(motion)
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect();
        w = w.array_f64("translations", &[t, j, 3], &rows)?;
    }
    for e in extras {
        w = w.array(e)?;
    }
    Ok(w.finish()?.into_inner())
}

/// The arrays of one archive, read as a clip; errors name the file.
struct Arrays<'a> {
    arrays: &'a [NpyArray],
    label: &'a Path,
}

impl<'a> Arrays<'a> {
    fn bad(&self, message: String) -> MotionError {
        ParseError {
            file: self.label.to_path_buf(),
            line: None,
            message,
        }
        .into()
    }

    fn find(&self, name: &str) -> Option<&'a NpyArray> {
        self.arrays.iter().find(|a| a.name == name)
    }

    fn need(&self, name: &str) -> Result<&'a NpyArray, MotionError> {
        self.find(name).ok_or_else(|| {
            self.bad(format!(
                "no array `{name}`: not a clip written by motionaug (an NPZ clip has \
                 `root_translation`, `rotations`, `fps` and `skeleton_json` or \
                 `parents`, `offsets` and `joint_names`)"
            ))
        })
    }

    /// float32 or float64 values of an array, which must have `shape`.
    fn floats(&self, name: &str, shape: &[usize]) -> Result<Vec<f64>, MotionError> {
        let a = self.need(name)?;
        if a.shape != shape {
            return Err(self.bad(format!(
                "array `{name}` has shape {:?}, expected {shape:?}",
                a.shape
            )));
        }
        a.to_f64()
            .or_else(|| a.to_f32().map(|v| v.into_iter().map(f64::from).collect()))
            .ok_or_else(|| self.bad(format!("array `{name}` is {:?}, not float", a.dtype)))
    }

    /// Vectors of 3 values from an array of shape `[.., 3]`.
    fn vectors(&self, name: &str, shape: &[usize]) -> Result<Vec<DVec3>, MotionError> {
        Ok(self
            .floats(name, shape)?
            .chunks_exact(3)
            .map(|p| DVec3::new(p[0], p[1], p[2]))
            .collect())
    }

    /// The skeleton of the lossless kind: `skeleton_json`.
    fn skeleton_json(&self, json: &NpyArray) -> Result<Skeleton, MotionError> {
        let bytes = json
            .to_u8()
            .ok_or_else(|| self.bad("array `skeleton_json` is not uint8".into()))?;
        let s: Skeleton = serde_json::from_slice(&bytes)
            .map_err(|e| self.bad(format!("array `skeleton_json`: {e}")))?;
        s.validated().map_err(|e| self.bad(e.to_string()))
    }

    /// The skeleton of the float32 kind: `joint_names`, `parents`, `offsets`,
    /// `end_sites` when there (metres; the source unit is the metre).
    fn skeleton_arrays(&self, j: usize) -> Result<Skeleton, MotionError> {
        let names = self
            .need("joint_names")?
            .to_strings()
            .ok_or_else(|| self.bad("array `joint_names` is not a string array".into()))?;
        let parents = self
            .need("parents")?
            .to_i32()
            .ok_or_else(|| self.bad("array `parents` is not int32".into()))?;
        let offsets = self.vectors("offsets", &[j, 3])?;
        // End sites came later: an archive without them has none.
        let end_sites = match self.find("end_sites") {
            Some(_) => self.vectors("end_sites", &[j, 3])?,
            None => vec![DVec3::NAN; j],
        };
        if names.len() != j || parents.len() != j {
            return Err(self.bad(format!(
                "{} joint names and {} parents for {j} joints",
                names.len(),
                parents.len()
            )));
        }
        let joints = (0..j)
            .map(|k| {
                let parent = match parents[k] {
                    -1 => None,
                    p if p >= 0 => Some(p as usize),
                    p => return Err(self.bad(format!("joint {k} has parent {p}"))),
                };
                Ok(Joint {
                    name: names[k].clone(),
                    parent,
                    offset: offsets[k],
                    channels: Vec::new(),
                    end_site: Some(end_sites[k]).filter(|e| !e.is_nan()),
                    limits: None,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Skeleton::new(joints, 1.0).map_err(|e| self.bad(e.to_string()))
    }
}

/// A clip from the arrays of an archive the product wrote: the lossless kind
/// (with `skeleton_json`) or the float32 kind (with `parents`, `offsets` and
/// `joint_names`); `label` names the file in errors.
pub fn motion_from_arrays(arrays: &[NpyArray], label: &Path) -> Result<Motion, MotionError> {
    let a = Arrays { arrays, label };
    let rotations_shape = a.need("rotations")?.shape.clone();
    let [t, j, 4] = rotations_shape[..] else {
        return Err(a.bad(format!(
            "array `rotations` has shape {rotations_shape:?}, expected [frames, joints, 4]"
        )));
    };
    let exact = a.find("skeleton_json");
    let skeleton = match exact {
        Some(json) => a.skeleton_json(json)?,
        None => a.skeleton_arrays(j)?,
    };
    if skeleton.len() != j {
        return Err(a.bad(format!(
            "`rotations` has {j} joints, the skeleton {}",
            skeleton.len()
        )));
    }
    let fps = a.floats("fps", &[])?[0];
    let root = a.vectors("root_translation", &[t, 3])?;
    let rot: Vec<DQuat> = a
        .floats("rotations", &[t, j, 4])?
        .chunks_exact(4)
        .map(|q| DQuat::from_xyzw(q[1], q[2], q[3], q[0]))
        .collect();
    let tracks: Tracks = match a.find("translations") {
        None => Vec::new(),
        Some(_) => {
            let rows = a.vectors("translations", &[t, j, 3])?;
            (0..j)
                .map(|k| {
                    let track: Vec<DVec3> = (0..t).map(|f| rows[f * j + k]).collect();
                    // Rows that hold the rest offset at every frame are no track.
                    let rest = skeleton.joint(k).offset;
                    let rest32 = rest.as_vec3().as_dvec3();
                    let still = track.iter().all(|p| *p == rest || *p == rest32);
                    (k > 0 && !still).then_some(track)
                })
                .collect()
        }
    };
    let mut motion = Motion::new(std::sync::Arc::new(skeleton), fps, root, rot.clone())
        .and_then(|m| m.with_tracks(tracks))
        .map_err(|e| a.bad(e.to_string()))?;
    if exact.is_some() {
        // `Motion::new` renormalises the quaternions, which can move their
        // last bit; put back the exact values it validated.
        for frame in 0..t {
            motion
                .pose_mut(frame)
                .copy_from_slice(&rot[frame * j..(frame + 1) * j]);
        }
    }
    Ok(motion)
}

/// A clip from `.npz` bytes the product wrote (see [`motion_from_arrays`]).
pub fn read_motion(bytes: &[u8], label: impl AsRef<Path>) -> Result<Motion, MotionError> {
    let label = label.as_ref();
    let arrays = read(bytes).map_err(|e| ParseError {
        file: label.to_path_buf(),
        line: None,
        message: format!("not a readable NPZ archive: {e}"),
    })?;
    motion_from_arrays(&arrays, label)
}

fn bad_data(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, message)
}

/// Parse one `.npy` file.
fn parse_npy(name: &str, bytes: &[u8]) -> std::io::Result<NpyArray> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad_data(format!("{name}: not a .npy file")));
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(bad_data(format!("{name}: unsupported .npy version {v}"))),
    };
    let header = bytes
        .get(start..start + header_len)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or_else(|| bad_data(format!("{name}: truncated header")))?;
    let field = |key: &str| -> Option<&str> {
        let at = header.find(&format!("'{key}'"))? + key.len() + 2;
        let rest = header[at..].trim_start().strip_prefix(':')?.trim_start();
        Some(rest)
    };
    let descr = field("descr")
        .and_then(|r| r.strip_prefix('\''))
        .and_then(|r| r.split('\'').next())
        .ok_or_else(|| bad_data(format!("{name}: no descr")))?;
    let dtype = DType::from_descr(descr)
        .ok_or_else(|| bad_data(format!("{name}: unsupported dtype {descr}")))?;
    if field("fortran_order").is_some_and(|r| r.starts_with("True")) {
        return Err(bad_data(format!("{name}: Fortran order is not supported")));
    }
    let shape_text = field("shape")
        .and_then(|r| r.strip_prefix('('))
        .and_then(|r| r.split(')').next())
        .ok_or_else(|| bad_data(format!("{name}: no shape")))?;
    let shape = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|_| bad_data(format!("{name}: bad shape ({shape_text})")))?;
    let count = shape
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b))
        .and_then(|n| n.checked_mul(dtype.size()))
        .ok_or_else(|| bad_data(format!("{name}: shape too large")))?;
    let data = bytes
        .get(start + header_len..start + header_len + count)
        .ok_or_else(|| bad_data(format!("{name}: data shorter than its shape")))?;
    Ok(NpyArray {
        name: name.to_string(),
        dtype,
        shape,
        data: data.to_vec(),
    })
}

/// Read every array of an `.npz` archive, in archive order.
pub fn read(bytes: &[u8]) -> std::io::Result<Vec<NpyArray>> {
    let mut zip = ZipArchive::new(Cursor::new(bytes)).map_err(std::io::Error::other)?;
    let mut out = Vec::with_capacity(zip.len());
    for i in 0..zip.len() {
        let mut file = zip.by_index(i).map_err(std::io::Error::other)?;
        let name = file
            .name()
            .map_err(std::io::Error::other)?
            .trim_end_matches(".npy")
            .to_string();
        let mut data = Vec::with_capacity(file.size().min(1 << 30) as usize);
        file.read_to_end(&mut data)?;
        out.push(parse_npy(&name, &data)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_headers_are_aligned_and_read_back() {
        let a = NpyArray::f32("x", &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let npy = a.to_npy();
        let header_len = u16::from_le_bytes([npy[8], npy[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0);
        assert_eq!(npy[10 + header_len - 1], b'\n');
        assert_eq!(parse_npy("x", &npy).unwrap(), a);
        let s = NpyArray::strings("n", &[2], &["Hips", "Ünter"]).unwrap();
        assert_eq!(s.dtype, DType::Unicode(5));
        assert_eq!(
            parse_npy("n", &s.to_npy()).unwrap().to_strings().unwrap(),
            vec!["Hips", "Ünter"]
        );
        assert!(NpyArray::f32("x", &[2, 2], &[1.0]).is_err());
    }

    #[test]
    fn archives_round_trip() {
        let bytes = NpzWriter::new(Cursor::new(Vec::new()))
            .array_i32("parents", &[3], &[-1, 0, 1])
            .unwrap()
            .array_bool("mask", &[1, 3], &[true, false, true])
            .unwrap()
            .scalar_f64("fps", 120.0)
            .unwrap()
            .finish()
            .unwrap()
            .into_inner();
        let arrays = read(&bytes).unwrap();
        assert_eq!(arrays.len(), 3);
        assert_eq!(arrays[0].to_i32().unwrap(), vec![-1, 0, 1]);
        assert_eq!(arrays[1].to_u8().unwrap(), vec![1, 0, 1]);
        assert_eq!(arrays[2].shape, Vec::<usize>::new());
        assert_eq!(arrays[2].to_f64().unwrap(), vec![120.0]);
        // Duplicate names are refused.
        let w = NpzWriter::new(Cursor::new(Vec::new()))
            .array_u8("a", &[1], &[1])
            .unwrap();
        assert!(w.array_u8("a", &[1], &[1]).is_err());
    }
}
