use std::path::Path;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let data = Path::new(&args[1]);
    let asf = Path::new(&args[2]);
    let calibrate = args.get(3).is_some_and(|a| a == "cal");
    let clip = motion::load(
        data,
        &motion::LoadOptions {
            skeleton: Some(asf.to_path_buf()),
            ..Default::default()
        },
    )
    .unwrap();
    let mut config = correct::CorrectConfig::default();
    config.physics.character.calibrate_feet = calibrate;
    let mut env = physics::ImitationEnv::new(&clip, &config.physics).unwrap();
    for b in &env.spec().feet {
        println!(
            "foot {} {:?} sole {:?}",
            b,
            env.spec().bodies[*b].shape,
            env.spec().sole_points(*b)
        );
    }
    let r = correct::deterministic_rollout(&mut env, |_, a| {
        a.fill(0.0);
        Ok(())
    })
    .unwrap();
    for (t, f) in r.feet.iter().enumerate() {
        let s: Vec<String> = f
            .iter()
            .map(|c| {
                format!(
                    "h{:+.3} t{:+.3} v{:.2} {}",
                    c.heel_m,
                    c.toe_m,
                    c.speed_m_s,
                    if c.touching { "T" } else { "." }
                )
            })
            .collect();
        println!("{t:3} {}", s.join("  |  "));
    }
}
