//! `motionaug view` on an augment output folder (kinematic recipe on the
//! bundled CMU walk) and a `motionaug correct` folder.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::{Value, json};

use crate::common::{motionaug, ok, root};
use crate::pixels::{canvas_diff, canvas_stats, colored_pixels, save};
use crate::webdriver::Browser;

/// The `view` server, stopped when dropped.
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `motionaug view PATHS --no-open --port 0`; its URL (the first line it prints).
fn view(paths: &[&Path]) -> (Server, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_motionaug"))
        .arg("view")
        .args(paths)
        .args(["--no-open", "--port", "0"])
        .current_dir(root())
        .stdout(Stdio::piped())
        .spawn()
        .expect("motionaug view starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().expect("stdout"))
        .read_line(&mut line)
        .expect("a line");
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("http://127.0.0.1:"))
        .unwrap_or_else(|| panic!("no URL in {line:?}"))
        .to_string();
    (Server(child), url)
}

async fn click(browser: &Browser, selector: &str) {
    let found = browser
        .eval(
            "const e = document.querySelector(arguments[0]); if (e) e.click(); return !!e;",
            vec![json!(selector)],
        )
        .await;
    assert_eq!(found, json!(true), "nothing matches {selector}");
}

/// Waits until `n` tracks are loaded and drawn.
async fn loaded(browser: &Browser, n: usize) {
    browser
        .wait_for(
            &format!(
                "window.__viewer.player.tracks.length === {n} && window.__viewer.player.tracks.every(t => t.loaded === t.frames && t.shownFrame >= 0 && (!t.clip.urls.flags || t.flags))"
            ),
            "the clips to load",
        )
        .await;
}

#[tokio::test(flavor = "multi_thread")]
async fn local_viewer_lists_plays_and_draws_a_correction() {
    let _one = crate::serial().await;
    crate::bundled();
    let Some(browser) = Browser::start().await else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let corr = tmp.path().join("corr");
    ok(motionaug(&[
        "augment",
        "examples/data/16_11_walk_veer_left.bvh",
        "--recipe",
        "examples/recipes/kinematic.toml",
        "--out",
        out.to_str().unwrap(),
    ]));
    ok(motionaug(&[
        "correct",
        "examples/data/16_11_walk_veer_left.bvh",
        "--out",
        corr.to_str().unwrap(),
        "--max-iterations",
        "1",
        "--envs",
        "2",
    ]));
    let (_server, url) = view(&[&out, &corr]);
    browser.goto(&url).await;
    browser.wait_for("window.__viewer.ready", "the page").await;

    // The list: every manifest entry, the source it names, the correction.
    let manifest: Vec<Value> =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    let mut expected: BTreeSet<String> = manifest
        .iter()
        .map(|e| {
            e["file"]
                .as_str()
                .unwrap()
                .trim_end_matches(".bvh")
                .to_string()
        })
        .collect();
    expected.insert("16_11_walk_veer_left".into());
    expected.insert("16_11_walk_veer_left (corrected)".into());
    let listed: BTreeSet<String> = serde_json::from_value(
        browser
            .eval(
                "return [...document.querySelectorAll('#clip-list li.clip')].map(li => li.dataset.name);",
                vec![],
            )
            .await,
    )
    .unwrap();
    assert_eq!(listed, expected);

    // A noise output plays beside its source: a skeleton is drawn, and it moves.
    click(
        &browser,
        "li.clip[data-name='16_11_walk_veer_left__00_noise_000']",
    )
    .await;
    loaded(&browser, 2).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let still = browser.screenshot().await;
    let stats = canvas_stats(&browser, &still).await;
    assert!(
        stats["saturated"].as_u64().unwrap() > 300,
        "no skeleton drawn: {stats}"
    );
    assert!(
        stats["colors"].as_u64().unwrap() > 20,
        "a blank canvas: {stats}"
    );
    save(&still, "viewer-local");
    let roles = browser
        .eval(
            "return window.__viewer.player.tracks.map(t => t.clip.role);",
            vec![],
        )
        .await;
    assert_eq!(roles, json!(["source", "synthesised"]));
    let links = browser
        .eval(
            "return document.querySelectorAll('#panels a.file').length;",
            vec![],
        )
        .await;
    assert_eq!(links, json!(2), "both files can be downloaded");
    let contacts = browser
        .eval(
            "return window.__viewer.player.tracks[0].flags.some(f => f & 2);",
            vec![],
        )
        .await;
    assert_eq!(contacts, json!(true), "the walk's planted feet are flagged");
    click(&browser, "#play").await;
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let moving = browser.screenshot().await;
    let changed = canvas_diff(&browser, &still, &moving).await;
    assert!(changed > 200, "only {changed} pixels changed while playing");
    // The clock runs (polled: on a loaded machine one read can land on a
    // frame drawn just as the loop came round).
    browser
        .wait_for("window.__viewer.player.time > 0", "the clock to run")
        .await;
    click(&browser, "#play").await;

    // A masked clip: occluded joints are flagged.
    click(
        &browser,
        "li.clip[data-name='16_11_walk_veer_left__04_mask_000']",
    )
    .await;
    loaded(&browser, 2).await;
    let occluded = browser
        .eval(
            "const t = window.__viewer.player.tracks[1]; return [t.meta.masked, t.flags.some(f => f & 1)];",
            vec![],
        )
        .await;
    assert_eq!(occluded, json!([true, true]));

    // An IK edit: effector, keyframe and target are marked.
    click(
        &browser,
        "li.clip[data-name='16_11_walk_veer_left__05_ik_000']",
    )
    .await;
    loaded(&browser, 2).await;
    let entry = manifest
        .iter()
        .find(|e| e["file"] == json!("16_11_walk_veer_left__05_ik_000.bvh"))
        .unwrap();
    let ik = browser
        .eval("return window.__viewer.player.tracks[1].meta.ik;", vec![])
        .await;
    assert_eq!(ik["keyframe"], entry["keyframe"], "{ik}");
    assert_eq!(ik["effector_name"], entry["effector"]);
    let marks = browser
        .eval(
            "return document.querySelectorAll('#keyframes .mark').length;",
            vec![],
        )
        .await;
    assert_eq!(marks, json!(1));
    browser
        .eval(
            "window.__viewer.player.seek(arguments[0]); return 0;",
            vec![json!(
                entry["keyframe"].as_f64().unwrap() / entry["fps"].as_f64().unwrap()
            )],
        )
        .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    save(&browser.screenshot().await, "viewer-ik");

    // Overlay puts every clip in the same place.
    click(&browser, "#overlay").await;
    let offsets = browser
        .eval(
            "return window.__viewer.player.tracks.every(t => t.offset.length() === 0);",
            vec![],
        )
        .await;
    assert_eq!(offsets, json!(true));
    click(&browser, "#overlay").await;

    // The correction: input and corrected clip, learning curve, criteria, bars.
    click(
        &browser,
        "li.clip[data-name='16_11_walk_veer_left (corrected)']",
    )
    .await;
    loaded(&browser, 2).await;
    browser
        .wait_for("document.querySelectorAll('.panel.curve canvas').length >= 2 && document.querySelector('table.criteria')", "the correction's panels")
        .await;
    let report: Value =
        serde_json::from_slice(&std::fs::read(corr.join("report.json")).unwrap()).unwrap();
    let points = browser
        .eval(
            "return document.querySelector('.panel.curve').plots[0].data[1];",
            vec![],
        )
        .await;
    let curve: Vec<f64> = report["curve"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p[2].as_f64().unwrap())
        .collect();
    assert_eq!(points, json!(curve));
    let drawn = colored_pixels(&browser, ".panel.curve canvas", [0x3b, 0x7c, 0xff]).await;
    assert!(
        drawn > 30,
        "the curve is not drawn ({drawn} pixels of its colour)"
    );
    let rows = browser
        .eval(
            "return document.querySelectorAll('table.criteria tr').length - 1;",
            vec![],
        )
        .await;
    assert_eq!(rows, json!(report["criteria"].as_array().unwrap().len()));
    let bars = browser
        .eval(
            "return document.querySelectorAll('svg.bars rect').length;",
            vec![],
        )
        .await;
    assert!(bars.as_u64().unwrap() >= 8, "{bars}");
    browser
        .eval(
            "document.querySelector('#panels').scrollIntoView(); return 0;",
            vec![],
        )
        .await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    save(&browser.screenshot().await, "viewer-correction");

    let errors = browser.console_errors().await;
    assert!(errors.is_empty(), "console errors: {errors:?}");
    browser.close().await;
}

/// Load time and frame rate of a 10-minute clip at 120 Hz (72 000 frames, the
/// bundled walk repeated) beside the 4.5 s walk itself, in one run. A
/// measurement, not a check: run it with
/// `cargo test --release -p motionaug-cli --test browser -- --ignored --nocapture`.
#[tokio::test(flavor = "multi_thread")]
#[ignore = "a measurement; prints figures"]
async fn measure_a_ten_minute_clip() {
    let _one = crate::serial().await;
    crate::bundled();
    let Some(browser) = Browser::start().await else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let walk = motion::load(
        crate::common::example("16_11_walk_veer_left.bvh"),
        &motion::LoadOptions::default(),
    )
    .unwrap();
    let frames = 10 * 60 * 120;
    let n = walk.frames();
    let root: Vec<_> = (0..frames)
        .map(|t| walk.root_translation()[t % n])
        .collect();
    let rotations: Vec<_> = (0..frames)
        .flat_map(|t| walk.pose(t % n).to_vec())
        .collect();
    let long = motion::Motion::new(walk.skeleton().clone(), walk.fps(), root, rotations).unwrap();
    motion::save(&long, tmp.path().join("ten_minutes.bvh")).unwrap();
    motion::save(&walk, tmp.path().join("walk.bvh")).unwrap();
    let (_server, url) = view(&[tmp.path()]);
    browser.goto(&url).await;
    browser.wait_for("window.__viewer.ready", "the page").await;
    println!("clip              frames  MB sent  load s  fps playing (1x)  pose ms  render ms");
    for name in ["walk", "ten_minutes"] {
        browser
            .eval(
                "window.__viewer.openedAt = performance.now(); return 0;",
                vec![],
            )
            .await;
        click(&browser, &format!("li.clip[data-name='{name}']")).await;
        let first = browser
            .wait_for(
                "window.__viewer.player.tracks.length === 1 && window.__viewer.player.tracks[0].shownFrame >= 0 && performance.now() - window.__viewer.openedAt",
                "the first frame",
            )
            .await;
        loaded(&browser, 1).await;
        let load = browser
            .eval("return window.__viewer.player.loadSeconds;", vec![])
            .await;
        let bytes = browser
            .eval("const t = window.__viewer.player.tracks[0]; return t.positions.byteLength + t.flags.byteLength;", vec![])
            .await;
        click(&browser, "#play").await;
        tokio::time::sleep(Duration::from_millis(500)).await;
        let start = browser
            .eval(
                "return [window.__viewer.player.rendered, performance.now()];",
                vec![],
            )
            .await;
        tokio::time::sleep(Duration::from_secs(5)).await;
        let end = browser
            .eval(
                "return [window.__viewer.player.rendered, performance.now()];",
                vec![],
            )
            .await;
        let costs = browser
            .eval(
                "return [window.__viewer.player.poseMs, window.__viewer.player.renderMs];",
                vec![],
            )
            .await;
        click(&browser, "#play").await;
        let fps = (end[0].as_f64().unwrap() - start[0].as_f64().unwrap())
            / ((end[1].as_f64().unwrap() - start[1].as_f64().unwrap()) / 1000.0);
        println!(
            "{name:<16} {:>7}  {:>7.1}  {:>6.2}  {fps:>5.1}            {:>6.2}  {:>6.2}   (first frame after {:.2} s)",
            browser
                .eval("return window.__viewer.player.tracks[0].frames;", vec![])
                .await,
            bytes.as_f64().unwrap() / 1e6,
            load.as_f64().unwrap(),
            costs[0].as_f64().unwrap(),
            costs[1].as_f64().unwrap(),
            first.as_f64().unwrap() / 1000.0,
        );
    }
    browser.close().await;
}
