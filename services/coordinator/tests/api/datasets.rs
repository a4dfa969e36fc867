//! Datasets: upload (BVH, ASF/AMC, zip), listing, deletion, limits, tenant isolation.

use crate::helpers::*;

#[tokio::test]
async fn upload_list_show_delete() {
    let app = spawn_app(&[]).await;
    let r = app
        .upload(
            &app.key,
            &[
                ("walk.bvh", bvh(40)),
                ("set.zip", zip_of(&[("dir/jump.bvh", bvh(12))])),
            ],
        )
        .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    let clips = body["clips"].as_array().unwrap();
    assert_eq!(clips.len(), 2);
    assert_eq!(clips[0]["name"], "walk");
    assert_eq!(clips[0]["frames"], 40);
    assert_eq!(clips[0]["joints"], 3);
    assert!((clips[0]["fps"].as_f64().unwrap() - 30.0).abs() < 0.01);
    assert_eq!(clips[1]["name"], "jump");
    assert_eq!(clips[1]["frames"], 12);
    let id = body["id"].as_str().unwrap();

    let list: Value = app.get_json("/v1/datasets").await;
    assert_eq!(list["datasets"].as_array().unwrap().len(), 1);
    assert_eq!(list["datasets"][0]["clip_count"], 2);
    let shown: Value = app.get_json(&format!("/v1/datasets/{id}")).await;
    assert_eq!(shown["clips"], body["clips"]);
    assert_eq!(shown["name"], "test set");

    let r = app
        .http
        .delete(app.url(&format!("/v1/datasets/{id}")))
        .bearer_auth(&app.key)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::NO_CONTENT);
    let r = app.get(&format!("/v1/datasets/{id}")).send().await.unwrap();
    assert_eq!(r.status(), StatusCode::NOT_FOUND);
    assert_eq!(app.dataset_count().await, 0);
    let clips: i64 = sqlx::query_scalar("SELECT count(*) FROM clips")
        .fetch_one(&app.db)
        .await
        .unwrap();
    assert_eq!(clips, 0);
    app.cleanup().await;
}

#[tokio::test]
async fn bad_files_reject_the_whole_upload_and_name_the_problem() {
    let app = spawn_app(&[]).await;
    // A broken frame line in the second file: nothing is stored.
    let mut broken = bvh(10);
    let text = String::from_utf8(broken.clone())
        .unwrap()
        .replace("Frame Time: 0.033333\n0.000", "Frame Time: 0.033333\nabc");
    broken = text.into_bytes();
    let r = app
        .upload(&app.key, &[("good.bvh", bvh(10)), ("bad.bvh", broken)])
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "bad.bvh");
    assert!(body["line"].as_u64().is_some(), "{body}");
    assert!(body["detail"].as_str().unwrap().contains("bad.bvh"));
    assert_eq!(app.dataset_count().await, 0);

    let r = app
        .upload(&app.key, &[("notes.txt", b"hello".to_vec())])
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(body["detail"].as_str().unwrap().contains("notes.txt"));

    let r = app
        .upload(
            &app.key,
            &[("a.bvh", bvh(5)), ("d.zip", zip_of(&[("x/a.bvh", bvh(5))]))],
        )
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        body["detail"].as_str().unwrap().contains("unique"),
        "{body}"
    );

    let r = app
        .upload(
            &app.key,
            &[(
                "motion.amc",
                b":FULLY-SPECIFIED\n1\nroot 0 0 0 0 0 0\n".to_vec(),
            )],
        )
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "motion.amc");

    let r = app
        .upload(&app.key, &[("junk.zip", b"PK not a zip".to_vec())])
        .await;
    assert_eq!(problem(r).await.0, StatusCode::UNPROCESSABLE_ENTITY);

    let r = app
        .http
        .post(app.url("/v1/datasets"))
        .bearer_auth(&app.key)
        .multipart(Form::new().text("name", "empty"))
        .send()
        .await
        .unwrap();
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["field"], "file");
    assert_eq!(app.dataset_count().await, 0);
    app.cleanup().await;
}

#[tokio::test]
async fn limits_on_body_size_file_count_and_frames() {
    let app = spawn_app(&[]).await;
    // Body limit is 1 MiB in these tests.
    let big = vec![b' '; 2 << 20];
    let r = app.upload(&app.key, &[("big.bvh", big)]).await;
    assert_eq!(problem(r).await.0, StatusCode::PAYLOAD_TOO_LARGE);
    // At most 5 files, zip entries included.
    let entries: Vec<(String, Vec<u8>)> = (0..6).map(|i| (format!("c{i}.bvh"), bvh(3))).collect();
    let refs: Vec<(&str, Vec<u8>)> = entries
        .iter()
        .map(|(n, b)| (n.as_str(), b.clone()))
        .collect();
    let r = app.upload(&app.key, &[("many.zip", zip_of(&refs))]).await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
    assert!(body["detail"].as_str().unwrap().contains("at most 5"));
    // At most 500 frames per clip.
    let r = app.upload(&app.key, &[("long.bvh", bvh(501))]).await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(body["file"], "long.bvh");
    // Recipes are JSON bodies with their own limit.
    let (dataset, _) = upload_one(&app).await;
    let huge = json!({"ops": [{"op": "noise", "pad": "x".repeat(5 << 20)}]});
    let r = app.augment(&dataset, &huge).await;
    assert_eq!(r.status(), StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(app.dataset_count().await, 1);
    app.cleanup().await;
}

fn example(name: &str) -> Vec<u8> {
    std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/data")
            .join(name),
    )
    .unwrap()
}

#[tokio::test]
async fn amc_clips_pair_with_the_asf_of_their_upload() {
    let app = spawn_app(&[]).await;
    let asf = example("HDM_bd.asf");
    let kick = example("HDM_bd_kickLFront1Reps_001_120.amc");
    // Two skeletons: the AMC takes the one whose name prefixes its own.
    let r = app
        .upload(
            &app.key,
            &[
                ("HDM_xx.asf", asf.clone()),
                ("HDM_bd.asf", asf.clone()),
                ("HDM_bd_kickLFront1Reps_001_120.amc", kick.clone()),
            ],
        )
        .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    assert_eq!(body["clips"].as_array().unwrap().len(), 1);
    assert_eq!(body["clips"][0]["name"], "HDM_bd_kickLFront1Reps_001_120");
    assert_eq!(body["clips"][0]["fps"], 120.0);
    assert_eq!(body["clips"][0]["joints"], 31);
    let skeleton: String = sqlx::query_scalar("SELECT skeleton_name FROM clips")
        .fetch_one(&app.db)
        .await
        .unwrap();
    assert_eq!(skeleton, "HDM_bd.asf");
    // Several skeletons and none fits: refused, naming the AMC.
    let r = app
        .upload(
            &app.key,
            &[
                ("a.asf", asf.clone()),
                ("b.asf", asf.clone()),
                ("kick.amc", kick.clone()),
            ],
        )
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "kick.amc");
    // A broken ASF is named with its line.
    let r = app
        .upload(
            &app.key,
            &[
                ("bad.asf", b":bonedata\n begin\n   id x\n".to_vec()),
                ("k.amc", kick),
            ],
        )
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "bad.asf");
    assert_eq!(app.dataset_count().await, 1);
    app.cleanup().await;
}

/// The upload limit, not the 4 MiB limit of JSON bodies, applies to uploads.
#[tokio::test]
async fn uploads_larger_than_json_bodies_are_accepted() {
    let app = spawn_app(&[
        ("MOTIONAUG_MAX_UPLOAD_BYTES", "16777216"),
        ("MOTIONAUG_MAX_FRAMES", "1000000"),
    ])
    .await;
    let big = bvh(150_000);
    assert!(big.len() > 5 << 20, "{} bytes", big.len());
    let r = app.upload(&app.key, &[("long.bvh", big)]).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    assert_eq!(body["clips"][0]["frames"], 150_000);
    app.cleanup().await;
}

#[tokio::test]
async fn tenants_never_see_each_other() {
    let app = spawn_app(&[]).await;
    let other = motionaug_coordinator::auth::create_key(&app.db, "beta")
        .await
        .unwrap();
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app.augment_json(&dataset, &noise_recipe()).await;
    let aug = aug["id"].as_str().unwrap();
    let as_other =
        |m: reqwest::Method, p: String| app.http.request(m, app.url(&p)).bearer_auth(&other);
    let list: Value = as_other(reqwest::Method::GET, "/v1/datasets".into())
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(list["datasets"].as_array().unwrap().len(), 0);
    for (method, path) in [
        (reqwest::Method::GET, format!("/v1/datasets/{dataset}")),
        (reqwest::Method::DELETE, format!("/v1/datasets/{dataset}")),
        (
            reqwest::Method::GET,
            format!("/v1/datasets/{dataset}/augmentations"),
        ),
        (reqwest::Method::GET, format!("/v1/augmentations/{aug}")),
        (
            reqwest::Method::GET,
            format!("/v1/augmentations/{aug}/events"),
        ),
        (
            reqwest::Method::GET,
            format!("/v1/augmentations/{aug}/results"),
        ),
        (reqwest::Method::DELETE, format!("/v1/augmentations/{aug}")),
    ] {
        let r = as_other(method.clone(), path.clone()).send().await.unwrap();
        assert_eq!(r.status(), StatusCode::NOT_FOUND, "{method} {path}");
    }
    let r = as_other(
        reqwest::Method::POST,
        format!("/v1/datasets/{dataset}/augmentations"),
    )
    .json(&noise_recipe())
    .send()
    .await
    .unwrap();
    assert_eq!(r.status(), StatusCode::NOT_FOUND);
    // Still there and untouched for its owner.
    assert_eq!(app.status(aug).await["status"], "queued");
    assert_eq!(app.dataset_count().await, 1);
    app.cleanup().await;
}

/// File names that are not bare file names, zip entries that point outside
/// the zip and stems that cannot name a clip (`...bvh` would be a clip `..`)
/// are refused with 422 naming them; nothing is cut down or stored.
#[tokio::test]
async fn unsafe_names_are_refused_naming_them() {
    let app = spawn_app(&[]).await;
    let names = [
        "...bvh",
        ".bvh",
        "../../etc/x.bvh",
        "/etc/abs.bvh",
        "..\\..\\evil.bvh",
        "my walk.bvh",
    ];
    for name in names {
        // Sent as curl sends it: the name as given, not percent-encoded.
        let form = Form::new()
            .part("file", Part::bytes(bvh(20)).file_name(name))
            .percent_encode_noop();
        let r = app
            .http
            .post(app.url("/v1/datasets"))
            .bearer_auth(&app.key)
            .multipart(form)
            .send()
            .await
            .unwrap();
        let (status, body) = problem(r).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{name}: {body}");
        // Named as sent, never cut to a stem (reqwest escapes `\` in the
        // quoted file name as `\\`, which the server reads literally).
        let file = body["file"].as_str().unwrap();
        assert!(
            file == name || file == name.replace('\\', "\\\\"),
            "{name}: {body}"
        );
        assert!(body["detail"].as_str().unwrap().contains(file), "{body}");
    }
    for entry in ["../../escape.bvh", "/abs.bvh", "dir/../../up.bvh"] {
        let zip = zip_of(&[("ok.bvh", bvh(20)), (entry, bvh(20))]);
        let r = app.upload(&app.key, &[("data.zip", zip)]).await;
        let (status, body) = problem(r).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{entry}: {body}");
        assert_eq!(body["file"], format!("data.zip/{entry}"), "{body}");
        assert!(body["detail"].as_str().unwrap().contains(entry), "{body}");
    }
    assert_eq!(app.dataset_count().await, 0);
    // Folders inside a zip are fine, and every stored name is a clip name.
    let zip = zip_of(&[("takes/run-1.v2.bvh", bvh(20))]);
    let r = app.upload(&app.key, &[("data.zip", zip)]).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    assert_eq!(body["clips"][0]["name"], "run-1.v2");
    app.cleanup().await;
}

/// Clips motionaug wrote as NPZ (the float32 output and the pipeline's
/// lossless form) upload like BVH, and so does the layout with a static root
/// above the travelling Hips; a file that is no clip is named.
#[tokio::test]
async fn npz_clips_and_a_static_root_layout_upload() {
    let app = spawn_app(&[]).await;
    let layered = example("static_root_walk.bvh");
    let walk = motion::io::parse_bvh(&layered, "w.bvh", motion::Unit::Auto).unwrap();
    let f32s = motion::npz::motion_to_bytes(&walk, &[]).unwrap();
    let exact = pipeline::encode_clip(&walk, None).unwrap();
    let r = app
        .upload(
            &app.key,
            &[
                ("static_root_walk.bvh", layered),
                ("walk_f32.npz", f32s.clone()),
                ("set.zip", zip_of(&[("dir/walk_exact.npz", exact)])),
            ],
        )
        .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    let clips = body["clips"].as_array().unwrap();
    let names: Vec<&str> = clips.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["static_root_walk", "walk_f32", "walk_exact"]);
    for c in clips {
        assert_eq!(
            (c["frames"].as_u64(), c["joints"].as_u64()),
            (Some(180), Some(31))
        );
        assert_eq!(c["fps"], 60.0);
    }
    let formats: Vec<String> = sqlx::query_scalar("SELECT format FROM clips ORDER BY position")
        .fetch_all(&app.db)
        .await
        .unwrap();
    assert_eq!(formats, ["bvh", "npz", "npz"]);
    let names: Vec<Value> = sqlx::query_scalar("SELECT joint_names FROM clips ORDER BY position")
        .fetch_all(&app.db)
        .await
        .unwrap();
    assert!(names.iter().all(|n| n[0] == "Hips"), "{names:?}");
    // Not a clip: refused, naming the file.
    let mut broken = f32s;
    broken.truncate(broken.len() / 2);
    let r = app.upload(&app.key, &[("broken.npz", broken)]).await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "broken.npz");
    assert!(
        body["detail"].as_str().unwrap().contains("broken.npz"),
        "{body}"
    );
    assert_eq!(app.dataset_count().await, 1);
    app.cleanup().await;
}
