//! Recipe parsing, validation errors and seeded expansion.

use synth::fixtures::walk;
use synth::*;

const TOML: &str = r#"
seed = 11

[[ops]]
op = "noise"
copies = 2
sigma_deg = 1.5

[[ops]]
op = "time_warp"
factor = [0.9, 1.1]

[[ops]]
op = "mirror"

[[ops]]
op = "mask"
mode = "random_joints"
p = 0.8
"#;

fn err_text(r: Result<Recipe, SynthError>) -> String {
    r.expect_err("expected an error").to_string()
}

#[test]
fn toml_and_json_give_the_same_recipe() {
    let a = Recipe::from_toml_str(TOML).unwrap();
    assert_eq!(a.seed, Some(11));
    assert_eq!(a.ops.len(), 4);
    assert_eq!(a.ops[0].copies, 2);
    assert_eq!(a.outputs_per_clip(), 5);
    let json = serde_json::to_string(&a).unwrap();
    let b = Recipe::from_json_str(&json).unwrap();
    assert_eq!(a, b);
    let c: Recipe = serde_json::from_str(&json).unwrap();
    assert_eq!(a, c);
    assert_eq!(a.effective_seed(None), 11);
    assert_eq!(a.effective_seed(Some(3)), 3);
}

#[test]
fn errors_name_the_op_and_field() {
    let e = err_text(Recipe::from_toml_str(
        "[[ops]]\nop = \"noise\"\nsigma = 2.0\n",
    ));
    assert!(e.contains("ops[0] (noise)") && e.contains("sigma"), "{e}");
    let e = err_text(Recipe::from_toml_str(
        "[[ops]]\nop = \"noise\"\n[[ops]]\nop = \"time_warp\"\nfactor = [1.1, 0.9]\n",
    ));
    assert!(
        e.contains("ops[1] (time_warp)") && e.contains("factor"),
        "{e}"
    );
    let e = err_text(Recipe::from_toml_str(
        "[[ops]]\nop = \"mask\"\nmode = \"random_joints\"\np = 2.0\n",
    ));
    assert!(e.contains("ops[0] (mask)") && e.contains("`p`"), "{e}");
    let e = err_text(Recipe::from_toml_str(
        "[[ops]]\nop = \"noise\"\ncopies = 0\n",
    ));
    assert!(e.contains("copies"), "{e}");
    let e = err_text(Recipe::from_toml_str("[[ops]]\nop = \"blur\"\n"));
    assert!(e.contains("unknown op `blur`"), "{e}");
    let e = err_text(Recipe::from_toml_str("[[ops]]\ncopies = 2\n"));
    assert!(e.contains("missing `op`"), "{e}");
    let e = err_text(Recipe::from_toml_str("sead = 1\n[[ops]]\nop = \"noise\"\n"));
    assert!(e.contains("unknown key `sead`"), "{e}");
    let e = err_text(Recipe::from_toml_str(
        "seed = -1\n[[ops]]\nop = \"noise\"\n",
    ));
    assert!(e.contains("seed"), "{e}");
    let e = err_text(Recipe::from_toml_str("seed = 1\n"));
    assert!(e.contains("ops"), "{e}");
    let e = err_text(Recipe::from_toml_str("[[ops]\nop = 1"));
    assert!(e.contains("TOML"), "{e}");
    let e = err_text(Recipe::from_json_str(
        r#"{"ops":[{"op":"mirror","axis":"y"}]}"#,
    ));
    assert!(
        e.contains("ops[0] (mirror)") && e.contains("axis") || e.contains("variant"),
        "{e}"
    );
}

#[test]
fn expansion_is_seeded_per_output_and_order_independent() {
    let r = Recipe::from_toml_str(TOML).unwrap();
    let m = walk(90, 30.0, 1.0);
    let a = expand_clip(&r, "walk", &m, 11).unwrap();
    let b = expand_clip(&r, "walk", &m, 11).unwrap();
    assert_eq!(a.len(), 5);
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.name, y.name);
        assert_eq!(x.output.motion, y.output.motion);
    }
    assert_eq!(a[0].name, "walk__00_noise_000");
    assert_eq!(a[1].name, "walk__00_noise_001");
    assert_ne!(a[0].output.motion, a[1].output.motion);
    // A single job run alone (as a worker would) equals the same output of the batch.
    let jobs = r.jobs("walk", 11);
    let alone = run_job(&r, "walk", &m, jobs[3]).unwrap();
    assert_eq!(alone.output.motion, a[3].output.motion);
    // Another clip name or seed changes the draws.
    let c = expand_clip(&r, "walk2", &m, 11).unwrap();
    assert_ne!(c[0].output.motion, a[0].output.motion);
    // Manifest entries carry the params and the drawn values.
    let e = a[2].manifest_entry("walk__01_time_warp_000.bvh", "walk.bvh");
    assert_eq!(e.op, "time_warp");
    assert!(e.sampled.contains_key("factor"));
    assert_eq!(e.params["factor"], serde_json::json!([0.9, 1.1]));
    let line = serde_json::to_value(&e).unwrap();
    assert!(line.get("effector").is_none());
}

mod properties {
    use proptest::prelude::*;
    use synth::*;

    fn range(lo: f64, hi: f64) -> impl Strategy<Value = Range> {
        (lo..hi, lo..hi).prop_map(|(a, b)| Range(a.min(b), a.max(b)))
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            (0.0..10.0f64, 0.0..0.1f64, any::<bool>()).prop_map(|(s, r, i)| Op::Noise(
                NoiseParams {
                    sigma_deg: s,
                    root_sigma_m: r,
                    include_root: i
                }
            )),
            range(0.5, 2.0).prop_map(|factor| Op::TimeWarp(TimeWarpParams { factor })),
            (0.0..0.2f64).prop_map(|t| Op::Mirror(MirrorParams {
                tolerance_m: t,
                ..MirrorParams::default()
            })),
            (0.0..1.0f64).prop_map(|p| Op::Mask(MaskParams::random_joints(p))),
            Just(Op::Mask(MaskParams::lower_body())),
            (
                range(0.0, 3.0),
                range(-2.0, 2.0),
                range(-3.0, 3.0),
                0.0..0.5f64
            )
                .prop_map(|(r, h, theta, j)| Op::Ik(IkParams {
                    preset: None,
                    effector: Some("foot".into()),
                    r: Some(r),
                    h: Some(h),
                    theta: Some(theta),
                    key_jitter_s: j,
                    ..IkParams::preset(ik::Preset::Kick)
                })),
        ]
    }

    proptest! {
        /// Any valid recipe survives TOML and JSON round trips unchanged.
        #[test]
        fn valid_recipes_round_trip(
            seed in proptest::option::of(any::<u64>()),
            ops in proptest::collection::vec((op(), 1u32..20), 1..6),
        ) {
            let ops = ops.into_iter().map(|(op, copies)| OpEntry { copies, op }).collect();
            let r = Recipe::new(seed, ops).unwrap();
            let json = serde_json::to_string(&r).unwrap();
            prop_assert_eq!(&Recipe::from_json_str(&json).unwrap(), &r);
            // TOML has no u64 above i64::MAX; such seeds are JSON-only.
            if seed.is_none_or(|s| s <= i64::MAX as u64) {
                let text = toml::to_string(&r).unwrap();
                prop_assert_eq!(&Recipe::from_toml_str(&text).unwrap(), &r);
            }
        }

        /// Arbitrary JSON never panics the parser.
        #[test]
        fn arbitrary_json_is_an_error_or_a_recipe(text in "\\PC{0,200}") {
            let _ = Recipe::from_json_str(&text);
            let _ = Recipe::from_toml_str(&text);
        }
    }
}
