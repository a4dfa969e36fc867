//! End-to-end checks on tiny models and short synthetic clips (fast), plus the
//! feature conversion on a real HDM05 clip.

use std::path::PathBuf;
use std::sync::Arc;

use candle_core::{DType, Device, Tensor};
use motion::glam::{DQuat, DVec3};
use motion::{Joint, Motion, Skeleton};
use vae::features::{FeatureConfig, clip_frames, frame_dim, frames_to_motion};
use vae::model::Vae;
use vae::{Prior, TrainConfig, TrainedVae, VaeConfig};

fn skeleton() -> Arc<Skeleton> {
    let joint = Joint::new;
    Arc::new(
        Skeleton::new(
            vec![
                joint("hips", None, DVec3::ZERO),
                joint("thigh", Some(0), DVec3::new(0.1, -0.1, 0.0)),
                joint("shin", Some(1), DVec3::new(0.0, -0.45, 0.0)),
            ],
            1.0,
        )
        .unwrap(),
    )
}

/// A kick-like clip: the thigh swings forward and back, the root walks a little.
fn clip(frames: usize, amplitude: f64, phase: f64) -> Motion {
    let s = skeleton();
    let mut root = Vec::new();
    let mut rot = Vec::new();
    for t in 0..frames {
        let u = t as f64 / frames as f64;
        let swing = amplitude * (std::f64::consts::TAU * u + phase).sin();
        root.push(DVec3::new(0.2 * u, 0.9 + 0.02 * swing, 0.5 * u));
        rot.push(DQuat::from_rotation_y(0.3 * u));
        rot.push(DQuat::from_rotation_x(-swing));
        rot.push(DQuat::from_rotation_x(0.5 * swing.abs()));
    }
    Motion::new(s, 30.0, root, rot).unwrap()
}

fn tiny_config(iterations: u64) -> TrainConfig {
    TrainConfig {
        model: VaeConfig::tiny(),
        iterations,
        seed: 11,
        ..TrainConfig::default()
    }
}

#[test]
fn network_shapes() {
    let cfg = VaeConfig::tiny();
    let f = frame_dim(3);
    let vae = Vae::new(&cfg, f, 0).unwrap();
    let x = Tensor::zeros((4, 7, f), DType::F32, &Device::Cpu).unwrap();
    let mask = Tensor::ones((4, 7), DType::F32, &Device::Cpu).unwrap();
    let (mu, lv) = vae.encoder.forward(&x, &mask).unwrap();
    assert_eq!(mu.dims(), &[4, cfg.latent]);
    assert_eq!(lv.dims(), &[4, cfg.latent]);
    assert_eq!(vae.decoder.forward(&mu, 9).unwrap().dims(), &[4, 9, f]);
    assert_eq!(vae.frame_disc.forward(&x, None).unwrap().dims(), &[4, 7]);
    assert_eq!(vae.seq_disc.forward(&x, &mask).unwrap().dims(), &[4]);
}

#[test]
fn padding_does_not_change_the_encoding() {
    let vae = Vae::new(&VaeConfig::tiny(), frame_dim(3), 2).unwrap();
    let f = frame_dim(3);
    let data: Vec<f32> = (0..5 * f)
        .map(|i| ((i * 37) % 11) as f32 / 5.0 - 1.0)
        .collect();
    let x = Tensor::from_vec(data.clone(), (1, 5, f), &Device::Cpu).unwrap();
    let ones = Tensor::ones((1, 5), DType::F32, &Device::Cpu).unwrap();
    let mut padded = data;
    padded.extend(vec![9.0f32; 3 * f]);
    let xp = Tensor::from_vec(padded, (1, 8, f), &Device::Cpu).unwrap();
    let mask =
        Tensor::from_vec(vec![1f32, 1., 1., 1., 1., 0., 0., 0.], (1, 8), &Device::Cpu).unwrap();
    let a = vae
        .encoder
        .forward(&x, &ones)
        .unwrap()
        .0
        .to_vec2::<f32>()
        .unwrap();
    let b = vae
        .encoder
        .forward(&xp, &mask)
        .unwrap()
        .0
        .to_vec2::<f32>()
        .unwrap();
    for (p, q) in a[0].iter().zip(&b[0]) {
        assert!((p - q).abs() < 1e-5, "{a:?} vs {b:?}");
    }
}

#[test]
fn a_tiny_vae_overfits_three_clips() {
    let clips = vec![clip(24, 0.8, 0.0), clip(30, 0.5, 1.0), clip(20, 1.0, 2.0)];
    let mut cfg = tiny_config(1);
    cfg.adversarial = false;
    cfg.optimizer = vae::OptimizerConfig::Adam { lr: 3e-3 };
    // Reconstruction alone, at a constant rate: what this test asks is whether
    // the trainer can fit its data.
    cfg.cosine_to = None;
    cfg.feet = vae::FootLoss::off();
    let before = vae::train(&clips, &cfg, |_| {})
        .unwrap()
        .reconstruction_error(&clips)
        .unwrap();
    cfg.iterations = 400;
    let mut first = None;
    let mut last = 0.0;
    let model = vae::train(&clips, &cfg, |p| {
        let l = p.losses.root + p.losses.rotation;
        first.get_or_insert(l);
        last = l;
    })
    .unwrap();
    let after = model.reconstruction_error(&clips).unwrap();
    let first = first.unwrap();
    assert!(last * 10.0 < first, "training loss {first} -> {last}");
    assert!(
        after.mean_joint_angle_rad * 2.5 < before.mean_joint_angle_rad,
        "{before:?} -> {after:?}"
    );
    assert!(
        after.root_rmse_m * 2.5 < before.root_rmse_m,
        "{before:?} -> {after:?}"
    );
    // Reconstructions have the clips' own lengths and the training skeleton.
    let recon = model.reconstruct(&clips).unwrap();
    assert_eq!(
        recon.iter().map(Motion::frames).collect::<Vec<_>>(),
        vec![24, 30, 20]
    );
}

#[test]
fn adversarial_training_runs_and_reports_its_terms() {
    let clips = vec![clip(16, 0.8, 0.0), clip(12, 0.5, 1.0)];
    let mut seen = vec![];
    vae::train(&clips, &tiny_config(5), |p| seen.push(*p.losses)).unwrap();
    assert_eq!(seen.len(), 5);
    assert!(
        seen.iter()
            .all(|l| l.discriminator > 0.0 && l.total.is_finite())
    );
    assert!(seen.iter().all(|l| l.mixed_adversarial == 0.0));
    // With the mixed-code terms on, the generator's term on mixed decodes is
    // reported and training stays finite.
    let mut cfg = tiny_config(5);
    cfg.weights.mixed_adversarial = 0.01;
    let mut mixed = vec![];
    vae::train(&clips, &cfg, |p| mixed.push(*p.losses)).unwrap();
    assert!(
        mixed
            .iter()
            .all(|l| l.mixed_adversarial != 0.0 && l.total.is_finite()),
        "{mixed:?}"
    );
    let mut cfg = tiny_config(2);
    cfg.adversarial = false;
    cfg.weights.mixed_adversarial = 0.01;
    vae::train(&clips, &cfg, |p| {
        assert_eq!(p.losses.discriminator, 0.0);
        assert_eq!(p.losses.mixed_adversarial, 0.0);
    })
    .unwrap();
}

#[test]
fn training_is_deterministic_and_save_load_keeps_samples() {
    let clips = vec![clip(16, 0.8, 0.0), clip(12, 0.5, 1.0), clip(14, 0.3, 2.0)];
    let a = vae::train(&clips, &tiny_config(8), |_| {}).unwrap();
    let b = vae::train(&clips, &tiny_config(8), |_| {}).unwrap();
    let dir = tempfile::tempdir().unwrap();
    a.save(dir.path()).unwrap();
    let loaded = TrainedVae::load(dir.path()).unwrap();
    for prior in [Prior::Near, Prior::Normal] {
        let s1 = a.sample(4, prior, 9).unwrap();
        let s2 = loaded.sample(4, prior, 9).unwrap();
        let s3 = b.sample(4, prior, 9).unwrap();
        for ((x, y), z) in s1.iter().zip(&s2).zip(&s3) {
            assert_eq!(x.motion, y.motion);
            assert_eq!(x.motion, z.motion);
            assert_eq!(x.z, y.z);
            assert!([16, 12, 14].contains(&x.motion.frames()));
        }
        let other = a.sample(4, prior, 10).unwrap();
        assert_ne!(other[0].z, s1[0].z);
    }
    assert_eq!(a.meta(), loaded.meta());
    // A damaged model directory is an error, not a panic.
    std::fs::write(dir.path().join("weights.safetensors"), b"junk").unwrap();
    assert!(TrainedVae::load(dir.path()).is_err());
}

#[test]
fn near_samples_are_closer_to_training_posteriors_than_prior_samples() {
    let clips: Vec<Motion> = (0..6)
        .map(|i| clip(12 + i, 0.3 + 0.1 * i as f64, i as f64))
        .collect();
    let model = vae::train(&clips, &tiny_config(30), |_| {}).unwrap();
    let mus = &model.meta().latents.mu;
    let nearest = |z: &[f32]| {
        mus.iter()
            .map(|m| {
                m.iter()
                    .zip(z)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f32>()
                    .sqrt()
            })
            .fold(f32::INFINITY, f32::min)
    };
    let mean = |model: &vae::TrainedVae, prior| {
        let s = model.sample(100, prior, 1).unwrap();
        s.iter().map(|s| nearest(&s.z)).sum::<f32>() / s.len() as f32
    };
    let (near, normal) = (mean(&model, Prior::Near), mean(&model, Prior::Normal));
    assert!(near < normal, "near {near} vs normal {normal}");
    // Near one training clip rather than between two: closer still.
    let dir = tempfile::tempdir().unwrap();
    model.save(dir.path()).unwrap();
    let single = vae::TrainedVae::load(dir.path())
        .unwrap()
        .with_near_members(1)
        .unwrap();
    let near_one = mean(&single, Prior::Near);
    assert!(near_one < near, "one member {near_one} vs two {near}");
    assert!(model.with_near_members(0).is_err());
}

#[test]
fn real_clip_features_round_trip_to_the_same_poses() {
    // The bundled copy of the HDM05 kick (also in ../shared/data/hdm05).
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
    let options = motion::LoadOptions {
        skeleton: Some(dir.join("HDM_bd.asf")),
        ..Default::default()
    };
    let m = motion::load(dir.join("HDM_bd_kickLFront1Reps_001_120.amc"), &options).unwrap();
    let config = FeatureConfig::default();
    let frames = clip_frames(&m, &config).unwrap();
    let back = frames_to_motion(m.skeleton(), config.fps, &frames).unwrap();
    let resampled = motion::resample::resample(&m, 30.0).unwrap();
    assert_eq!(back.frames(), resampled.frames());
    // The same poses, turned by the heading normalisation about the vertical.
    let turn = DQuat::from_rotation_y(-vae::features::heading(resampled.rotation(0, 0)));
    for t in (0..back.frames()).step_by(7) {
        let a = resampled.world_positions(t);
        let b = back.world_positions(t);
        for j in 1..a.len() {
            let d = (turn * (a[j] - a[0]) - (b[j] - b[0])).length();
            assert!(d < 1e-4, "frame {t} joint {j}: {d}");
        }
        assert!((a[0].y - b[0].y).abs() < 1e-4);
    }
}

/// A static root above the travelling Hips: the reader makes the Hips the
/// root, so the VAE sees the walk's own root path (the same features as the
/// walk written the usual way); its samples keep the file's static root
/// through save and load, so they are written back in the file's layout.
#[test]
fn a_static_root_above_the_hips_trains_and_samples_as_the_walk() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
    let layered = motion::load(dir.join("static_root_walk.bvh"), &Default::default()).unwrap();
    let walk = motion::load(dir.join("16_11_walk_veer_left.bvh"), &Default::default()).unwrap();
    let walk60 = motion::resample::resample(&walk, 60.0).unwrap();
    let config = FeatureConfig::default();
    let (a, b) = (
        clip_frames(&layered, &config).unwrap(),
        clip_frames(&walk60, &config).unwrap(),
    );
    // The layered file holds the walk's first 3 s: the same features over them.
    assert!(a.len() <= b.len());
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-4, "{x} vs {y}");
    }
    let model = vae::train(std::slice::from_ref(&layered), &tiny_config(4), |_| {}).unwrap();
    let saved = tempfile::tempdir().unwrap();
    model.save(saved.path()).unwrap();
    let loaded = TrainedVae::load(saved.path()).unwrap();
    let sample = &loaded.sample(1, Prior::Near, 3).unwrap()[0].motion;
    assert_eq!(sample.skeleton().joint(0).name, "Hips");
    assert_eq!(sample.skeleton().base()[0].name, "joint_Root");
    let text = motion::bvh::to_bytes(sample);
    assert!(text.starts_with(b"HIERARCHY\nROOT joint_Root\n"));
}

/// Mean pose speed (m/s, joints relative to the root) of clips.
fn pose_speed(clips: &[Motion]) -> f64 {
    clips
        .iter()
        .map(|m| motion::metrics::plausibility(m).pose_speed_m_s)
        .sum::<f64>()
        / clips.len() as f64
}

#[test]
fn the_mixed_motion_term_keeps_codes_between_out_of_phase_clips_moving() {
    // Swings half a period apart: a decoder that averages them between their
    // codes renders an in-between that barely moves; the term asks it to move
    // like its parents.
    let clips: Vec<Motion> = (0..6)
        .map(|i| {
            clip(
                24,
                0.9,
                if i % 2 == 0 {
                    0.0
                } else {
                    std::f64::consts::PI
                },
            )
        })
        .collect();
    let speed_of = |mixed_motion: f64| {
        let mut cfg = tiny_config(300);
        cfg.adversarial = false;
        cfg.feet = vae::FootLoss::off();
        cfg.weights.mixed_motion = mixed_motion;
        let mut reported = vec![];
        let model = vae::train(&clips, &cfg, |p| reported.push(p.losses.mixed_motion)).unwrap();
        let samples: Vec<Motion> = model
            .sample_decoded(24, Prior::Near, 3)
            .unwrap()
            .into_iter()
            .map(|s| s.motion)
            .collect();
        (pose_speed(&samples), reported)
    };
    let originals = pose_speed(&clips);
    let (off, reported_off) = speed_of(0.0);
    let (on, reported_on) = speed_of(1.0);
    assert!(reported_off.iter().all(|&l| l == 0.0));
    assert!(reported_on.iter().all(|l| l.is_finite()) && reported_on[0] > 0.0);
    assert!(
        on > off && (originals - on).abs() < (originals - off).abs(),
        "pose speed: originals {originals:.3}, samples without the term {off:.3}, with it {on:.3}"
    );
}

/// A leg with a foot (so the foot terms are on), `lift` m above the ground.
fn footed_clip(frames: usize, lift: f64, phase: f64) -> Motion {
    let joint = |name: &str, parent, offset, end_site| Joint {
        name: name.into(),
        parent,
        offset,
        channels: vec![],
        end_site,
        limits: None,
    };
    let s = Arc::new(
        Skeleton::new(
            vec![
                joint("hips", None, DVec3::ZERO, None),
                joint("thigh", Some(0), DVec3::new(0.1, -0.1, 0.0), None),
                joint("shin", Some(1), DVec3::new(0.0, -0.45, 0.0), None),
                joint(
                    "foot",
                    Some(2),
                    DVec3::new(0.0, -0.45, 0.0),
                    Some(DVec3::new(0.0, 0.0, 0.1)),
                ),
            ],
            1.0,
        )
        .unwrap(),
    );
    let mut root = Vec::new();
    let mut rot = Vec::new();
    for t in 0..frames {
        let u = t as f64 / frames as f64;
        let swing = 0.3 * (std::f64::consts::TAU * u + phase).sin();
        root.push(DVec3::new(0.0, 1.0 + lift, 0.5 * u));
        rot.extend([
            DQuat::IDENTITY,
            DQuat::from_rotation_x(-swing),
            DQuat::from_rotation_x(0.5 * swing.abs()),
            DQuat::IDENTITY,
        ]);
    }
    Motion::new(s, 30.0, root, rot).unwrap()
}

#[test]
fn the_mixed_contact_term_is_reported_and_trained_down_only_when_on() {
    // Clips standing on the ground and clips hovering 20 cm up: codes between
    // them are asked to stand on the ground in as many frames as their parents.
    let clips: Vec<Motion> = (0..6)
        .map(|i| footed_clip(24, if i % 2 == 0 { 0.0 } else { 0.2 }, i as f64))
        .collect();
    let reported = |mixed_contact: f64| {
        let mut cfg = tiny_config(200);
        cfg.adversarial = false;
        cfg.features.floor = None;
        cfg.weights.mixed_contact = mixed_contact;
        let mut out = vec![];
        vae::train(&clips, &cfg, |p| out.push(p.losses.mixed_contact)).unwrap();
        out
    };
    assert!(reported(0.0).iter().all(|&l| l == 0.0));
    let on = reported(1.0);
    assert!(on.iter().all(|l| l.is_finite()) && on[0] > 0.0, "{on:?}");
    let (first, last) = (
        on[..20].iter().sum::<f32>(),
        on[on.len() - 20..].iter().sum::<f32>(),
    );
    assert!(
        last < 0.5 * first,
        "contact term {first} -> {last} over 20 iterations"
    );
}

/// The leg of `footed_clip` standing still on its ankle (4 cm up) with the
/// foot pitched by `pitch` rad (toe down for > 0), the hips swaying 2 cm.
fn standing_clip(frames: usize, pitch: f64, phase: f64) -> Motion {
    let walking = footed_clip(frames, 0.0, phase);
    let mut root = Vec::new();
    let mut rot = Vec::new();
    for t in 0..frames {
        let u = t as f64 / frames as f64;
        let sway = 0.02 * (std::f64::consts::TAU * u + phase).sin();
        root.push(DVec3::new(sway, 1.04, 0.0));
        rot.extend([
            DQuat::IDENTITY,
            DQuat::IDENTITY,
            DQuat::IDENTITY,
            DQuat::from_rotation_x(pitch),
        ]);
    }
    Motion::new(walking.skeleton().clone(), 30.0, root, rot).unwrap()
}

/// Trains `clips` with a mixed-code term off, weighed next to nothing (it
/// only reports) and weighed 10, and checks that it reports 0 when off, a
/// finite value above `floor` when watched, and that training on it halves
/// its last 20 values. `set` sets the term's weight, `read` reads its loss.
fn check_mixed_term_trains(
    clips: &[Motion],
    floor: f32,
    set: impl Fn(&mut TrainConfig, f64),
    read: impl Fn(&vae::Losses) -> f32,
) {
    let reported = |weight: f64| {
        let mut cfg = tiny_config(150);
        cfg.adversarial = false;
        cfg.features.floor = None;
        set(&mut cfg, weight);
        let mut out = vec![];
        vae::train(clips, &cfg, |p| out.push(read(p.losses))).unwrap();
        out
    };
    assert!(reported(0.0).iter().all(|&l| l == 0.0));
    let tail = |v: &[f32]| v[v.len() - 20..].iter().sum::<f32>() / 20.0;
    let watched = reported(1e-9);
    let trained = reported(10.0);
    assert!(watched.iter().all(|l| l.is_finite()), "{watched:?}");
    assert!(tail(&watched) > floor, "{watched:?}");
    assert!(
        tail(&trained) < 0.5 * tail(&watched),
        "term {} with weight 10, {} without",
        tail(&trained),
        tail(&watched)
    );
}

#[test]
fn the_mixed_sole_term_is_reported_and_pulls_planted_feet_level() {
    // Clips standing toe-down and clips standing heel-down: codes between
    // two of them are asked to stand at the clips' mean pitch, level.
    let clips: Vec<Motion> = (0..6)
        .map(|i| standing_clip(24, if i % 2 == 0 { 0.4 } else { -0.4 }, i as f64))
        .collect();
    check_mixed_term_trains(
        &clips,
        0.1,
        |c, w| c.weights.mixed_sole = w,
        |l| l.mixed_sole,
    );
}

#[test]
fn the_mixed_travel_term_is_reported_and_trains_the_root_path() {
    // Walks at two speeds: codes between two of them are asked to travel,
    // quarter by quarter, at the mean of their parents' speeds.
    let clips: Vec<Motion> = (0..6)
        .map(|i| {
            let mut walk = footed_clip(24, 0.0, i as f64);
            let fast = if i % 2 == 0 { 1.0 } else { 3.0 };
            for p in walk.root_translation_mut() {
                p.z *= fast;
            }
            walk
        })
        .collect();
    check_mixed_term_trains(
        &clips,
        0.01,
        |c, w| c.weights.mixed_travel = w,
        |l| l.mixed_travel,
    );
}

#[test]
fn the_mixed_balance_term_is_reported_and_keeps_the_body_over_its_foot() {
    // The leg of `footed_clip` gliding upright at 0.5 or 1.5 m/s, its foot
    // under the hips: never accelerating, the zero moment point stays over
    // the sole. Decodes between two of them that jitter accelerate, and
    // their zero moment point leaves the sole; the term smooths them.
    let clips: Vec<Motion> = (0..6)
        .map(|i| {
            let leg = footed_clip(24, 0.0, 0.0);
            let speed = if i % 2 == 0 { 0.5 } else { 1.5 };
            let root = (0..24)
                .map(|t| DVec3::new(0.0, 1.04, speed * t as f64 / 30.0))
                .collect();
            let still = vec![DQuat::IDENTITY; 24 * 4];
            Motion::new(leg.skeleton().clone(), 30.0, root, still).unwrap()
        })
        .collect();
    // The character: 1 kg at the hips, 1 kg at the ankle, a 20 x 17 cm sole
    // 4 cm under the ankle.
    let model = vae::BalanceModel {
        bodies: vec![
            vae::balance::MassPoint {
                joint: 0,
                offset: [0.0, 0.0, 0.0],
                mass_kg: 1.0,
            },
            vae::balance::MassPoint {
                joint: 3,
                offset: [0.0, 0.0, 0.0],
                mass_kg: 1.0,
            },
        ],
        soles: vec![vae::balance::SoleCorners {
            joint: 3,
            corners: [
                [-0.1, -0.04, -0.05],
                [0.1, -0.04, -0.05],
                [-0.1, -0.04, 0.12],
                [0.1, -0.04, 0.12],
            ],
        }],
        touch_m: 0.02,
    };
    check_mixed_term_trains(
        &clips,
        0.01,
        |c, w| {
            c.weights.mixed_balance = w;
            c.balance = Some(model.clone());
        },
        |l| l.mixed_balance,
    );
    // The weight without the model is refused, not ignored.
    let mut cfg = tiny_config(1);
    cfg.weights.mixed_balance = 1.0;
    assert!(vae::train(&clips, &cfg, |_| {}).is_err());
}
