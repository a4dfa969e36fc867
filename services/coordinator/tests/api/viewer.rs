//! The viewer's routes: the page itself without a key, libraries and clip
//! parts for the owner only, and a correction's learning curve while it trains
//! (the worker's `curve.json`) and once it has finished (its report's).

use crate::helpers::*;

#[tokio::test]
async fn the_page_is_served_without_a_key() {
    let app = spawn_app(&[]).await;
    let page = app.http.get(app.url("/viewer/")).send().await.unwrap();
    assert_eq!(page.status(), StatusCode::OK);
    assert!(page.text().await.unwrap().contains("main.js"));
    let redirect = reqwest::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .build()
        .unwrap()
        .get(app.url("/viewer"))
        .send()
        .await
        .unwrap();
    assert_eq!(redirect.status(), StatusCode::PERMANENT_REDIRECT);
    let info = app.public_json("/viewer/api/info").await;
    assert_eq!(info["mode"], "service");
    let missing = app
        .http
        .get(app.url("/viewer/nothing.js"))
        .send()
        .await
        .unwrap();
    assert_eq!(missing.status(), StatusCode::NOT_FOUND);
    app.cleanup().await;
}

#[tokio::test]
async fn dataset_clips_play_for_their_tenant_only() {
    let app = spawn_app(&[]).await;
    let (dataset, body) = upload_one(&app).await;
    let clip = body["clips"][0]["id"].as_str().unwrap();
    let library: Value = app
        .get_json(&format!("/v1/datasets/{dataset}/library"))
        .await;
    assert_eq!(library["clips"][0]["name"], "walk");
    assert_eq!(library["clips"][0]["role"], "source");
    let meta_url = library["clips"][0]["urls"]["meta"]
        .as_str()
        .unwrap()
        .to_string();
    assert_eq!(
        meta_url,
        format!("/v1/datasets/{dataset}/clips/{clip}/view/meta")
    );
    let meta: Value = app.get_json(&meta_url).await;
    // Hips, Spine, Head and the head's end site.
    assert_eq!(meta["points"].as_array().unwrap().len(), 4);
    assert_eq!(meta["frames"], 40);
    let frames = app
        .get(&format!(
            "/v1/datasets/{dataset}/clips/{clip}/view/frames?start=10&count=5"
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(frames.status(), StatusCode::OK);
    assert_eq!(frames.bytes().await.unwrap().len(), 5 * 4 * 12);
    let flags = app
        .get(&format!("/v1/datasets/{dataset}/clips/{clip}/view/flags"))
        .send()
        .await
        .unwrap();
    assert_eq!(flags.bytes().await.unwrap().len(), 40 * 4);
    let past = app
        .get(&format!(
            "/v1/datasets/{dataset}/clips/{clip}/view/frames?start=40"
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(past.status(), StatusCode::BAD_REQUEST);

    let other = motionaug_coordinator::auth::create_key(&app.db, "other")
        .await
        .unwrap();
    for path in [format!("/v1/datasets/{dataset}/library"), meta_url.clone()] {
        let r = app
            .http
            .get(app.url(&path))
            .bearer_auth(&other)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::NOT_FOUND, "{path}");
    }
    app.cleanup().await;
}

#[tokio::test]
async fn corrections_show_their_live_curve_then_their_report() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;
    let recipe = json!({"seed": 1, "ops": [{"op": "noise", "copies": 1}],
                        "correct": {"time_budget_s": 1, "envs": 2}});
    let aug = app.augment_json(&dataset, &recipe).await;
    let aug = aug["id"].as_str().unwrap();
    let job: Value = app
        .worker(reqwest::Method::POST, "/jobs/claim")
        .json(&json!({"worker_id": "w", "kinds": ["correct_original"], "wait_ms": 0}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let (id, epoch) = (job["id"].as_str().unwrap(), job["epoch"].as_i64().unwrap());
    let put = |name: &str, body: Vec<u8>| {
        app.worker(
            reqwest::Method::PUT,
            &format!("/jobs/{id}/artifacts/{name}?epoch={epoch}"),
        )
        .body(body)
        .send()
    };
    let library = |app: &TestApp| {
        let path = format!("/v1/augmentations/{aug}/library");
        let request = app.get(&path);
        async move { request.send().await.unwrap().json::<Value>().await.unwrap() }
    };
    let before = library(&app).await;
    let original = before["corrections"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["key"] == "correct_original:walk")
        .cloned()
        .expect("the original's correction is listed");
    assert_eq!(original["state"], "running");
    assert_eq!(original["curve"], json!([]));

    let live = json!([[2.0, 1024.0, 0.31], [4.0, 2048.0, 0.52]]);
    let r = put(
        "work/originals/walk/curve.json",
        live.to_string().into_bytes(),
    )
    .await
    .unwrap();
    assert!(r.status().is_success(), "{}", r.status());
    let during = library(&app).await;
    let original = &during["corrections"].as_array().unwrap()[0];
    assert_eq!(original["key"], "correct_original:walk");
    assert_eq!(original["curve"], live);
    assert_eq!(original["accepted"], Value::Null);

    // Once the report is there, its curve (from action 0 on) is the one shown.
    let report = json!({"curve": [[0.0, 0.0, 0.2], [2.0, 1024.0, 0.31], [4.0, 2048.0, 0.52], [6.0, 3072.0, 0.71]],
                        "accepted": true});
    let r = put(
        "work/originals/walk/report.json",
        report.to_string().into_bytes(),
    )
    .await
    .unwrap();
    assert!(r.status().is_success());
    let after = library(&app).await;
    let original = &after["corrections"].as_array().unwrap()[0];
    assert_eq!(original["curve"], report["curve"]);
    assert_eq!(original["accepted"], true);
    let file = app
        .get(&format!(
            "/v1/augmentations/{aug}/files/work/originals/walk/report.json"
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(file.json::<Value>().await.unwrap(), report);

    let other = motionaug_coordinator::auth::create_key(&app.db, "other")
        .await
        .unwrap();
    for path in [
        format!("/v1/augmentations/{aug}/library"),
        format!("/v1/augmentations/{aug}/files/work/originals/walk/report.json"),
    ] {
        let r = app
            .http
            .get(app.url(&path))
            .bearer_auth(&other)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::NOT_FOUND, "{path}");
    }
    app.cleanup().await;
}
