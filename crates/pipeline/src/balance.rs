//! The simulated character's masses and soles for the VAE's balance term.
//!
//! Why it exists: the vae crate measures whether a decoded motion could stand
//! (`vae::balance`) with the character the correction simulates, but knows
//! nothing of physics; this crate knows both, so it hands the character
//! builder's bodies over as plain numbers.

use motion::Motion;
use physics::{CharacterOptions, CharacterSpec, Shape};

use crate::PipelineError;

/// Give `config` the balance model its mixed-balance weight asks for (none
/// when the weight is 0 or there is no clip): the correction's default
/// character for the first clip's skeleton, touching within the
/// correction's sole tolerance. Every trainer of the VAE (the CLI, the
/// recipe's vae stage, the eval table) goes through here.
pub fn add_vae_balance_model(
    config: &mut vae::TrainConfig,
    clips: &[Motion],
) -> Result<(), PipelineError> {
    if let (true, Some(first)) = (config.weights.mixed_balance > 0.0, clips.first()) {
        config.balance = Some(vae_balance_model(
            first,
            &CharacterOptions::default(),
            correct::AcceptanceConfig::default().sole_tolerance_m as f32,
        )?);
    }
    Ok(())
}

/// The character `options` builds for `clip`'s skeleton, its feet calibrated
/// on `clip` when the options ask (as the correction's environment does):
/// each body's mass at its centre in its driving joint's frame, each foot
/// box's bottom corners, and `touch_m` (the correction's sole tolerance is
/// what `motionaug metrics --balance` uses).
pub fn vae_balance_model(
    clip: &Motion,
    options: &CharacterOptions,
    touch_m: f32,
) -> Result<vae::BalanceModel, PipelineError> {
    let mut spec = CharacterSpec::build(clip.skeleton().clone(), options)
        .map_err(correct::CorrectError::from)?;
    if options.calibrate_feet {
        spec.calibrate_feet(clip);
    }
    let bodies = spec
        .bodies
        .iter()
        .map(|b| vae::balance::MassPoint {
            joint: b.driver,
            offset: b.com_local.to_array(),
            mass_kg: b.mass,
        })
        .collect();
    let mut soles = Vec::new();
    for &f in &spec.feet {
        let body = &spec.bodies[f];
        let Shape::Box {
            center,
            half_extents: h,
            rotation,
        } = body.shape
        else {
            continue;
        };
        let corner = |sx: f32, sz: f32| {
            (center + rotation * glam::Vec3::new(sx * h.x, -h.y, sz * h.z)).to_array()
        };
        soles.push(vae::balance::SoleCorners {
            joint: body.driver,
            corners: [
                corner(-1.0, -1.0),
                corner(1.0, -1.0),
                corner(-1.0, 1.0),
                corner(1.0, 1.0),
            ],
        });
    }
    if soles.is_empty() {
        return Err(PipelineError::Job(format!(
            "the balance term needs feet: the character of {} joints has no foot box",
            clip.joints()
        )));
    }
    Ok(vae::BalanceModel {
        bodies,
        soles,
        touch_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor};
    use std::path::PathBuf;

    fn bundled(name: &str) -> Motion {
        let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/data"));
        let options = motion::io::LoadOptions {
            skeleton: Some(dir.join("HDM_bd.asf")),
            ..Default::default()
        };
        motion::io::load(dir.join(name), &options).expect("bundled clip")
    }

    /// The VAE's tensor measure and `motionaug metrics --balance` (the
    /// physics crate's, on the correction's environment) read the same
    /// clip alike: the same supported frames, the same mean distance.
    #[test]
    fn the_vae_measures_a_clips_balance_as_the_correction_does() {
        let acceptance = correct::AcceptanceConfig::default();
        let physics = physics::Config::default();
        for name in [
            "HDM_bd_jogLeftCircle4StepsRstart_001_120.amc",
            "HDM_bd_kickLFront1Reps_001_120.amc",
        ] {
            let clip = bundled(name);
            let model = vae_balance_model(
                &clip,
                &physics.character,
                acceptance.sole_tolerance_m as f32,
            )
            .unwrap();
            let features = vae::FeatureConfig {
                floor: None,
                ..Default::default()
            };
            let frames = vae::features::clip_frames(&clip, &features).unwrap();
            let dim = vae::features::frame_dim(clip.joints());
            let n = frames.len() / dim;
            let raw = Tensor::from_vec(frames, (1, n, dim), &Device::Cpu).unwrap();
            let mask = Tensor::ones((1, n), candle_core::DType::F32, &Device::Cpu).unwrap();
            let balance = vae::balance::Balance::new(&model, clip.skeleton()).unwrap();
            let (mean, supported) = balance.zmp_outside(&raw, &mask, features.fps).unwrap();
            let mean = mean.to_vec1::<f32>().unwrap()[0] as f64;
            let supported = supported.to_vec1::<f32>().unwrap()[0] as f64;
            let theirs = correct::acceptance::input_balance(&clip, &physics, &acceptance).unwrap();
            let their_mean = theirs.outside_sum_m / theirs.supported_frames.max(1) as f64;
            let frames = theirs.supported_frames as f64;
            eprintln!("{name}: {supported} / {frames} frames, {mean:.4} / {their_mean:.4} m");
            assert!(
                (supported - frames).abs() <= 0.1 * frames,
                "{name}: {supported} supported frames against {frames}"
            );
            assert!(
                (mean - their_mean).abs() <= 0.02 + 0.1 * their_mean,
                "{name}: {mean:.3} m outside against {their_mean:.3}"
            );
        }
    }
}
