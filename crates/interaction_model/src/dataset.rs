//! The training data: variations of each captured pair made by the
//! interaction optimiser ([`interaction::retarget`]), cached on disk so that
//! training and evaluation never re-run the optimiser.
//!
//! **Making it** ([`build_pair`]): both clips are resampled to `fps` (30, the
//! rate the networks work at) and retargeted at every global scale of the grid
//! `scale_min, scale_min + scale_step, ..., scale_max` (the paper's 0.75..1.25
//! in steps of 0.05), `repeats` times per grid value: the first repeat is the
//! uniform body, the others add a per-bone jitter (left and right equal, see
//! [`interaction::dataset::draw_scale`]). Each variation keeps the points of
//! both output bodies (joint points and end sites, [`interaction::layout`]),
//! B's per-point bone factor and the optimiser's own report figures (wall
//! time, JPD, foot skating) for the comparison with the learned model.
//!
//! **On disk** ([`Dataset::save`]): `dataset.json` (configuration, bodies, key
//! pairs, per-variation scales and figures) and one `<pair>.npz` per pair
//! (`template_a` `[T, Pa, 3]`, `template_b`, `a` `[V, T, Pa, 3]`, `b`,
//! `factors` `[V, Pb]`, float32, metres; readable with `numpy.load`).
//!
//! **Windows** ([`Dataset::windows`], [`Dataset::batch`]): training samples are
//! `window`-frame pieces of a variation at a stride. Each window is put in a
//! canonical frame fixed by its *template* (the captured source): origin
//! between the two roots at the first frame, on the ground, and turned about y
//! so that B's root lies along +x from A's ([`Canon`]).

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use glam::{DQuat, DVec3};
use interaction::layout::{Layout, PointKind, locked_joints};
use interaction::{BoneScale, RetargetOptions, VariationSpec};
use motion::Motion;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use candle_core::{Device, Tensor};

use crate::error::{ModelError, Result};

pub const FORMAT: u32 = 1;
pub const MANIFEST: &str = "dataset.json";

/// How the variations are drawn.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DatasetConfig {
    pub fps: f64,
    pub scale_min: f64,
    pub scale_max: f64,
    pub scale_step: f64,
    /// Variations per grid scale (the first uniform, the rest jittered).
    pub repeats: usize,
    pub bone_jitter: f64,
    pub seed: u64,
    pub retarget: RetargetOptions,
}

impl Default for DatasetConfig {
    fn default() -> Self {
        DatasetConfig {
            fps: 30.0,
            scale_min: 0.75,
            scale_max: 1.25,
            scale_step: 0.05,
            repeats: 3,
            bone_jitter: 0.04,
            seed: 0,
            retarget: RetargetOptions::default(),
        }
    }
}

impl DatasetConfig {
    /// The grid of global scales.
    pub fn grid(&self) -> Result<Vec<f64>> {
        let ok = self.scale_step > 0.0
            && self.scale_min.is_finite()
            && self.scale_max >= self.scale_min
            && self.repeats > 0
            && self.fps.is_finite()
            && self.fps > 0.0;
        if !ok {
            return Err(ModelError::Config {
                field: "dataset",
                message: format!(
                    "need scale_min <= scale_max, scale_step > 0, repeats > 0, fps > 0 (got {:?})",
                    (
                        self.scale_min,
                        self.scale_max,
                        self.scale_step,
                        self.repeats,
                        self.fps
                    )
                ),
            });
        }
        let n = ((self.scale_max - self.scale_min) / self.scale_step + 1e-6).floor() as usize;
        Ok((0..=n)
            .map(|k| ((self.scale_min + k as f64 * self.scale_step) * 1e6).round() / 1e6)
            .collect())
    }
}

/// The graph of one body's points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Body {
    /// Joint name, or `<joint>_end` for an end site.
    pub names: Vec<String>,
    /// Parent point (-1 for the root).
    pub parents: Vec<i32>,
    /// Per point: the skeleton joint whose factor scales its bone.
    pub joints: Vec<String>,
}

impl Body {
    pub fn of(skeleton: &motion::Skeleton, layout: &Layout) -> Body {
        let mut names = Vec::new();
        let mut parents = Vec::new();
        let mut joints = Vec::new();
        for p in &layout.points {
            match *p {
                PointKind::Joint(j) => {
                    names.push(skeleton.joint(j).name.clone());
                    parents.push(
                        skeleton
                            .parent(j)
                            .map_or(-1, |q| layout.joint_point[q] as i32),
                    );
                    joints.push(skeleton.joint(j).name.clone());
                }
                PointKind::EndSite(j) => {
                    names.push(format!("{}_end", skeleton.joint(j).name));
                    parents.push(layout.joint_point[j] as i32);
                    joints.push(skeleton.joint(j).name.clone());
                }
            }
        }
        Body {
            names,
            parents,
            joints,
        }
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Per-point factors of a bone scale (1 at the root).
    pub fn factors(&self, skeleton: &motion::Skeleton, scale: &BoneScale) -> Result<Vec<f32>> {
        let f = scale.factors(skeleton)?;
        self.joints
            .iter()
            .zip(&self.parents)
            .map(|(name, &p)| {
                if p < 0 {
                    return Ok(1.0);
                }
                let j = skeleton.find(name).ok_or_else(|| {
                    ModelError::Data(format!("the skeleton has no joint `{name}`"))
                })?;
                Ok(f[j] as f32)
            })
            .collect()
    }

    /// The bone scale given by per-point factors (the inverse of [`Body::factors`];
    /// a joint's own point wins over its end site).
    pub fn scale_of(&self, factors: &[f32]) -> Result<BoneScale> {
        let mut bones = BTreeMap::new();
        for (i, name) in self.joints.iter().enumerate() {
            if self.parents[i] < 0 {
                continue;
            }
            let is_end = self.names[i].ends_with("_end") && self.names[i] != *name;
            if is_end && bones.contains_key(name) {
                continue;
            }
            bones.insert(name.clone(), factors[i] as f64);
        }
        let s = BoneScale {
            default: 1.0,
            bones,
        };
        s.validate()?;
        Ok(s)
    }
}

/// A key joint pair in point indices and frames of the dataset's rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyPoints {
    pub a_joint: String,
    pub b_joint: String,
    pub a: usize,
    pub b: usize,
    pub first: usize,
    pub last: usize,
}

/// One variation's scale and the optimiser's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VariationMeta {
    pub scale: BoneScale,
    /// The grid value (global factor before jitter).
    pub global: f64,
    pub wall_s: f64,
    pub jpd_m: Option<f64>,
    pub foot_skating_a_m_s: f64,
    pub foot_skating_b_m_s: f64,
    pub bone_error_m: f64,
}

/// One pair's data (points in metres, world frame).
#[derive(Debug, Clone)]
pub struct PairData {
    pub name: String,
    pub fps: f64,
    pub frames: usize,
    pub body_a: Body,
    pub body_b: Body,
    pub key_pairs: Vec<KeyPoints>,
    pub source_foot_skating: (f64, f64),
    /// `[T, Pa, 3]` and `[T, Pb, 3]`: the captured source.
    pub template_a: Vec<f32>,
    pub template_b: Vec<f32>,
    pub variations: Vec<VariationMeta>,
    /// Per variation `[T, Pa, 3]`, `[T, Pb, 3]`, `[Pb]`.
    pub a: Vec<Vec<f32>>,
    pub b: Vec<Vec<f32>>,
    pub factors: Vec<Vec<f32>>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct PairMeta {
    name: String,
    fps: f64,
    frames: usize,
    body_a: Body,
    body_b: Body,
    key_pairs: Vec<KeyPoints>,
    source_foot_skating: (f64, f64),
    variations: Vec<VariationMeta>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Manifest {
    format: u32,
    config: DatasetConfig,
    pairs: Vec<PairMeta>,
    build_wall_s: f64,
}

/// Every pair's data.
#[derive(Debug, Clone)]
pub struct Dataset {
    pub config: DatasetConfig,
    pub pairs: Vec<PairData>,
    pub build_wall_s: f64,
}

fn flat_points(p: &[DVec3]) -> Vec<f32> {
    p.iter()
        .flat_map(|v| [v.x as f32, v.y as f32, v.z as f32])
        .collect()
}

/// Layout of a body as the optimiser sees it (locks from the source clip).
pub fn layout_of(skeleton: &motion::Skeleton, source: &Motion) -> Layout {
    Layout::new(skeleton, &locked_joints(source), source.pose(0))
}

/// The key pairs of a source pair, in points.
pub fn key_points(a: &Motion, b: &Motion, options: &RetargetOptions) -> Result<Vec<KeyPoints>> {
    let (la, lb) = (layout_of(a.skeleton(), a), layout_of(b.skeleton(), b));
    Ok(
        interaction::contact::key_pairs(a, b, &la, &lb, &options.key_pairs)?
            .into_iter()
            .map(|k| KeyPoints {
                a: la.joint_point[k.a],
                b: lb.joint_point[k.b],
                a_joint: k.a_joint,
                b_joint: k.b_joint,
                first: k.first_frame,
                last: k.last_frame,
            })
            .collect(),
    )
}

/// Variations of one pair (see the module doc). `a`, `b` at any frame rate.
pub fn build_pair(name: &str, a: &Motion, b: &Motion, config: &DatasetConfig) -> Result<PairData> {
    let span = tracing::info_span!("interaction_dataset_pair", pair = name);
    let _guard = span.enter();
    interaction::retarget::check_pair(a, b)?;
    let grid = config.grid()?;
    let a = motion::resample::resample(a, config.fps)?;
    let b = motion::resample::resample(b, config.fps)?;
    let (la, lb) = (layout_of(a.skeleton(), &a), layout_of(b.skeleton(), &b));
    let body_a = Body::of(a.skeleton(), &la);
    let body_b = Body::of(b.skeleton(), &lb);
    let mut scales = Vec::new();
    for (k, &g) in grid.iter().enumerate() {
        for r in 0..config.repeats {
            let index = k * config.repeats + r;
            let spec = VariationSpec {
                count: 1,
                scale_min: g,
                scale_max: g,
                bone_jitter: if r == 0 { 0.0 } else { config.bone_jitter },
                grid: false,
                seed: config.seed,
            };
            let s = interaction::dataset::draw_scale(&spec, b.skeleton(), index)?;
            scales.push((g, s));
        }
    }
    let results: Vec<Result<_>> = scales
        .par_iter()
        .map(|(g, s)| {
            let r = interaction::retarget(&a, &b, s, &config.retarget)?;
            let lb_out = layout_of(r.b.skeleton(), &b);
            let meta = VariationMeta {
                scale: s.clone(),
                global: *g,
                wall_s: r.report.wall_s,
                jpd_m: r.report.jpd_m,
                foot_skating_a_m_s: r.report.foot_skating.a_output_m_s,
                foot_skating_b_m_s: r.report.foot_skating.b_output_m_s,
                bone_error_m: r.report.bone_error_m,
            };
            Ok((
                meta,
                flat_points(&la.all_positions(&r.a)),
                flat_points(&lb_out.all_positions(&r.b)),
                body_b.factors(b.skeleton(), s)?,
            ))
        })
        .collect();
    let mut data = PairData {
        name: name.to_string(),
        fps: config.fps,
        frames: a.frames(),
        key_pairs: key_points(&a, &b, &config.retarget)?,
        source_foot_skating: (
            motion::metrics::plausibility(&a).foot_skating_m_s,
            motion::metrics::plausibility(&b).foot_skating_m_s,
        ),
        template_a: flat_points(&la.all_positions(&a)),
        template_b: flat_points(&lb.all_positions(&b)),
        body_a,
        body_b,
        variations: Vec::new(),
        a: Vec::new(),
        b: Vec::new(),
        factors: Vec::new(),
    };
    for r in results {
        let (meta, pa, pb, f) = r?;
        data.variations.push(meta);
        data.a.push(pa);
        data.b.push(pb);
        data.factors.push(f);
    }
    Ok(data)
}

impl Dataset {
    /// Build from named pairs (clips at any rate); the pairs must share a body graph.
    pub fn build(pairs: &[(String, Motion, Motion)], config: &DatasetConfig) -> Result<Dataset> {
        let start = Instant::now();
        let mut out = Vec::new();
        for (name, a, b) in pairs {
            out.push(build_pair(name, a, b, config)?);
        }
        let d = Dataset {
            config: config.clone(),
            pairs: out,
            build_wall_s: start.elapsed().as_secs_f64(),
        };
        d.check()?;
        Ok(d)
    }

    /// Every pair has the same body graphs (one network serves them all).
    pub fn check(&self) -> Result<()> {
        let Some(first) = self.pairs.first() else {
            return Err(ModelError::Data("the dataset has no pairs".into()));
        };
        for p in &self.pairs {
            if p.body_a.parents != first.body_a.parents || p.body_b.parents != first.body_b.parents
            {
                return Err(ModelError::Data(format!(
                    "pair `{}` has another skeleton graph than `{}`",
                    p.name, first.name
                )));
            }
            let (ta, tb) = (p.frames * p.body_a.len() * 3, p.frames * p.body_b.len() * 3);
            let ok = p.template_a.len() == ta
                && p.template_b.len() == tb
                && p.a.len() == p.variations.len()
                && p.a.iter().all(|x| x.len() == ta)
                && p.b.iter().all(|x| x.len() == tb)
                && p.factors.iter().all(|x| x.len() == p.body_b.len());
            if !ok {
                return Err(ModelError::Data(format!(
                    "pair `{}`: array sizes do not match its frames and bodies",
                    p.name
                )));
            }
        }
        Ok(())
    }

    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| ModelError::io(dir, e))?;
        let mut metas = Vec::new();
        for p in &self.pairs {
            let (t, pa, pb, v) = (p.frames, p.body_a.len(), p.body_b.len(), p.variations.len());
            let cat = |x: &[Vec<f32>]| x.concat();
            let io = |e| ModelError::io(dir.join(format!("{}.npz", p.name)), e);
            let w = motion::npz::NpzWriter::new(std::io::Cursor::new(Vec::new()))
                .array_f32("template_a", &[t, pa, 3], &p.template_a)
                .map_err(io)?
                .array_f32("template_b", &[t, pb, 3], &p.template_b)
                .map_err(io)?
                .array_f32("a", &[v, t, pa, 3], &cat(&p.a))
                .map_err(io)?
                .array_f32("b", &[v, t, pb, 3], &cat(&p.b))
                .map_err(io)?
                .array_f32("factors", &[v, pb], &cat(&p.factors))
                .map_err(io)?;
            let bytes = w.finish().map_err(io)?.into_inner();
            motion::io::write_atomic(&dir.join(format!("{}.npz", p.name)), &bytes)?;
            metas.push(PairMeta {
                name: p.name.clone(),
                fps: p.fps,
                frames: p.frames,
                body_a: p.body_a.clone(),
                body_b: p.body_b.clone(),
                key_pairs: p.key_pairs.clone(),
                source_foot_skating: p.source_foot_skating,
                variations: p.variations.clone(),
            });
        }
        let manifest = Manifest {
            format: FORMAT,
            config: self.config.clone(),
            pairs: metas,
            build_wall_s: self.build_wall_s,
        };
        write_json(&dir.join(MANIFEST), &manifest)
    }

    pub fn load(dir: &Path) -> Result<Dataset> {
        let path = dir.join(MANIFEST);
        let text = std::fs::read_to_string(&path).map_err(|e| ModelError::io(&path, e))?;
        let m: Manifest = serde_json::from_str(&text).map_err(|source| ModelError::Json {
            path: path.clone(),
            source,
        })?;
        if m.format != FORMAT {
            return Err(ModelError::Data(format!(
                "{}: format {} (this build reads {FORMAT})",
                path.display(),
                m.format
            )));
        }
        let mut pairs = Vec::new();
        for meta in m.pairs {
            let file = dir.join(format!("{}.npz", meta.name));
            let bytes = std::fs::read(&file).map_err(|e| ModelError::io(&file, e))?;
            let arrays = motion::npz::read(&bytes).map_err(|e| ModelError::io(&file, e))?;
            let get = |name: &str| -> Result<Vec<f32>> {
                arrays
                    .iter()
                    .find(|a| a.name == name)
                    .and_then(|a| a.to_f32())
                    .ok_or_else(|| {
                        ModelError::Data(format!("{}: no float32 array `{name}`", file.display()))
                    })
            };
            let v = meta.variations.len();
            let split = |x: Vec<f32>| -> Result<Vec<Vec<f32>>> {
                if v == 0 || !x.len().is_multiple_of(v) {
                    return Err(ModelError::Data(format!(
                        "{}: {} values for {v} variations",
                        file.display(),
                        x.len()
                    )));
                }
                Ok(x.chunks(x.len() / v).map(|c| c.to_vec()).collect())
            };
            pairs.push(PairData {
                template_a: get("template_a")?,
                template_b: get("template_b")?,
                a: split(get("a")?)?,
                b: split(get("b")?)?,
                factors: split(get("factors")?)?,
                name: meta.name,
                fps: meta.fps,
                frames: meta.frames,
                body_a: meta.body_a,
                body_b: meta.body_b,
                key_pairs: meta.key_pairs,
                source_foot_skating: meta.source_foot_skating,
                variations: meta.variations,
            });
        }
        let d = Dataset {
            config: m.config,
            pairs,
            build_wall_s: m.build_wall_s,
        };
        d.check()?;
        Ok(d)
    }

    /// Windows of `window` frames every `stride` frames of every variation
    /// that `keep(pair, variation)` accepts. A clip shorter than a window
    /// gives one window (its last frame held).
    pub fn windows(
        &self,
        window: usize,
        stride: usize,
        keep: impl Fn(usize, usize) -> bool,
    ) -> Vec<Sample> {
        let stride = stride.max(1);
        let mut out = Vec::new();
        for (p, pair) in self.pairs.iter().enumerate() {
            let starts = window_starts(pair.frames, window, stride);
            for v in 0..pair.variations.len() {
                if keep(p, v) {
                    out.extend(starts.iter().map(|&start| Sample {
                        pair: p,
                        variation: v,
                        start,
                    }));
                }
            }
        }
        out
    }

    /// Tensors of a set of windows (see [`Batch`]).
    pub fn batch(&self, samples: &[Sample], window: usize) -> Result<Batch> {
        let first = self
            .pairs
            .first()
            .ok_or_else(|| ModelError::Data("empty dataset".into()))?;
        let (va, vb) = (first.body_a.len(), first.body_b.len());
        let n = samples.len();
        let mut ta = Vec::with_capacity(n * window * va * 3);
        let mut tb = Vec::with_capacity(n * window * vb * 3);
        let mut oa = Vec::with_capacity(n * window * va * 3);
        let mut ob = Vec::with_capacity(n * window * vb * 3);
        let mut sc = Vec::with_capacity(n * vb);
        let mut canons = Vec::with_capacity(n);
        for s in samples {
            let p = &self.pairs[s.pair];
            let tw_a = cut(&p.template_a, p.frames, va, s.start, window);
            let tw_b = cut(&p.template_b, p.frames, vb, s.start, window);
            let canon = Canon::of(&tw_a[0..3], &tw_b[0..3]);
            ta.extend(canon.apply(&tw_a));
            tb.extend(canon.apply(&tw_b));
            oa.extend(canon.apply(&cut(&p.a[s.variation], p.frames, va, s.start, window)));
            ob.extend(canon.apply(&cut(&p.b[s.variation], p.frames, vb, s.start, window)));
            sc.extend_from_slice(&p.factors[s.variation]);
            canons.push(canon);
        }
        let t =
            |v: Vec<f32>, nodes: usize| Tensor::from_vec(v, (n, window, nodes, 3), &Device::Cpu);
        Ok(Batch {
            template_a: t(ta, va)?,
            template_b: t(tb, vb)?,
            a: t(oa, va)?,
            b: t(ob, vb)?,
            scales: Tensor::from_vec(sc, (n, vb), &Device::Cpu)?,
            samples: samples.to_vec(),
            canons,
        })
    }
}

/// Start frames of the windows of a clip of `frames` frames; the last window
/// ends at the clip's end.
pub fn window_starts(frames: usize, window: usize, stride: usize) -> Vec<usize> {
    if frames <= window {
        return vec![0];
    }
    let last = frames - window;
    let mut s: Vec<usize> = (0..=last).step_by(stride.max(1)).collect();
    if s.last() != Some(&last) {
        s.push(last);
    }
    s
}

/// Frames `start..start + window` of `[T, P, 3]` data (the last frame held past the end).
pub fn cut(data: &[f32], frames: usize, points: usize, start: usize, window: usize) -> Vec<f32> {
    let row = points * 3;
    let mut out = Vec::with_capacity(window * row);
    for f in 0..window {
        let t = (start + f).min(frames - 1);
        out.extend_from_slice(&data[t * row..(t + 1) * row]);
    }
    out
}

/// One training sample: a window of one variation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    pub pair: usize,
    pub variation: usize,
    pub start: usize,
}

/// A batch of windows in their canonical frames: templates and optimiser
/// outputs `[n, window, P, 3]`, B's factors `[n, Pb]`.
pub struct Batch {
    pub template_a: Tensor,
    pub template_b: Tensor,
    pub a: Tensor,
    pub b: Tensor,
    pub scales: Tensor,
    pub samples: Vec<Sample>,
    pub canons: Vec<Canon>,
}

/// The canonical frame of a window (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Canon {
    pub origin: DVec3,
    pub turn: DQuat,
}

impl Canon {
    /// From the roots of A and B at the window's first frame.
    pub fn of(root_a: &[f32], root_b: &[f32]) -> Canon {
        let a = DVec3::new(root_a[0] as f64, 0.0, root_a[2] as f64);
        let b = DVec3::new(root_b[0] as f64, 0.0, root_b[2] as f64);
        let d = b - a;
        let angle = if d.length() > 1e-6 {
            d.z.atan2(d.x)
        } else {
            0.0
        };
        Canon {
            origin: (a + b) * 0.5,
            turn: DQuat::from_rotation_y(angle),
        }
    }

    /// World -> canonical, on flat xyz triples.
    pub fn apply(&self, xyz: &[f32]) -> Vec<f32> {
        xyz.chunks(3)
            .flat_map(|p| {
                let v =
                    self.turn * (DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) - self.origin);
                [v.x as f32, v.y as f32, v.z as f32]
            })
            .collect()
    }

    /// Canonical -> world.
    pub fn invert(&self, xyz: &[f32]) -> Vec<f32> {
        let back = self.turn.inverse();
        xyz.chunks(3)
            .flat_map(|p| {
                let v = back * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) + self.origin;
                [v.x as f32, v.y as f32, v.z as f32]
            })
            .collect()
    }
}

pub(crate) fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let mut json = serde_json::to_vec_pretty(value).map_err(|source| ModelError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    json.push(b'\n');
    Ok(motion::io::write_atomic(path, &json)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_frame_round_trips_and_faces_x() {
        let c = Canon::of(&[1.0, 0.9, 2.0], &[1.0, 0.95, 4.0]);
        let b = c.apply(&[1.0, 0.95, 4.0]);
        assert!((b[0] - 1.0).abs() < 1e-5 && b[2].abs() < 1e-5, "{b:?}");
        let p = [0.3f32, 1.2, -0.7, 2.0, 0.1, 0.4];
        let back = c.invert(&c.apply(&p));
        for (x, y) in p.iter().zip(&back) {
            assert!((x - y).abs() < 1e-5);
        }
    }

    #[test]
    fn windows_cover_the_clip() {
        assert_eq!(window_starts(10, 4, 3), vec![0, 3, 6]);
        assert_eq!(window_starts(11, 4, 3), vec![0, 3, 6, 7]);
        assert_eq!(window_starts(3, 4, 3), vec![0]);
        let d: Vec<f32> = (0..6).map(|x| x as f32).collect(); // 2 frames of 1 point
        assert_eq!(
            cut(&d, 2, 1, 1, 3),
            vec![3.0, 4.0, 5.0, 3.0, 4.0, 5.0, 3.0, 4.0, 5.0]
        );
    }

    #[test]
    fn grid_matches_the_paper() {
        let g = DatasetConfig::default().grid().unwrap();
        assert_eq!(g.len(), 11);
        assert_eq!(g[0], 0.75);
        assert_eq!(g[10], 1.25);
        assert_eq!(g[5], 1.0);
    }
}
