//! The generated OpenAPI document against the routes the router really serves.

use crate::helpers::*;

/// The methods a router may answer; HEAD and OPTIONS follow from these.
const METHODS: [reqwest::Method; 5] = [
    reqwest::Method::GET,
    reqwest::Method::POST,
    reqwest::Method::PUT,
    reqwest::Method::DELETE,
    reqwest::Method::PATCH,
];

/// The path of every route of `router`, read from its `Debug` text, where
/// axum's path router lists them as `RouteId(n): "/path"` (the fallback
/// router that follows is left out).
fn routed_paths(router: &impl std::fmt::Debug) -> BTreeSet<String> {
    let text = format!("{router:?}");
    let (paths, _fallback) = text
        .split_once(", fallback_router:")
        .expect("axum's Router lists its path router first");
    paths
        .split("RouteId(")
        .skip(1)
        .filter_map(|rest| {
            let (id, after) = rest.split_once(')')?;
            let quoted = after.strip_prefix(": \"")?;
            id.parse::<u32>().ok()?;
            Some(quoted.split('"').next()?.to_string())
        })
        .collect()
}

/// A concrete URL path that the route `path` matches.
fn concrete(path: &str) -> String {
    path.split('/')
        .map(|segment| match segment {
            "{id}" => "00000000-0000-0000-0000-000000000000",
            s if s.starts_with("{*") => "probe/file.bin",
            s if s.starts_with('{') => "probe",
            s => s,
        })
        .collect::<Vec<_>>()
        .join("/")
}

/// Every path the router serves, with every method it answers, is an operation
/// of the served OpenAPI document, and the document has no other operation.
/// Paths come from the router itself, methods from asking the running app
/// (without credentials: an answered method is anything but 405, and never the
/// router's "route not found").
#[tokio::test]
async fn every_route_and_method_is_in_the_openapi_document() {
    let app = spawn_app(&[]).await;
    let spec: Value = app.public_json("/openapi.json").await;
    let documented: BTreeMap<String, BTreeSet<String>> = spec["paths"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(path, item)| {
            let methods = METHODS
                .iter()
                .map(|m| m.as_str().to_lowercase())
                .filter(|m| item.get(m).is_some())
                .collect();
            (path.clone(), methods)
        })
        .collect();

    let paths = routed_paths(&startup::router(app.state.clone()));
    assert!(
        paths.len() >= documented.len() && paths.contains("/internal/v1/jobs/{id}/inputs/{*name}"),
        "cannot read the routes from the router: {paths:?}"
    );
    let mut routed: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for path in &paths {
        let mut methods = BTreeSet::new();
        for method in METHODS {
            let url = app.url(&concrete(path));
            let r = app.http.request(method.clone(), url).send().await.unwrap();
            let status = r.status();
            if status == StatusCode::METHOD_NOT_ALLOWED {
                continue;
            }
            let body = r.text().await.unwrap();
            assert!(
                !(status == StatusCode::NOT_FOUND && body.contains("route not found")),
                "{method} {path}: the probe missed its route"
            );
            methods.insert(method.as_str().to_lowercase());
        }
        routed.insert(spec_path(path), methods);
    }
    assert_eq!(routed, documented);
    app.cleanup().await;
}

/// What the document says beyond its paths: every operation has a unique id,
/// the worker API needs the worker token, every client error is a problem, and
/// every reference resolves.
#[tokio::test]
async fn the_openapi_document_is_complete() {
    let app = spawn_app(&[]).await;
    let spec: Value = app.public_json("/openapi.json").await;
    assert_eq!(spec["openapi"], "3.1.0");
    assert_eq!(spec["security"], serde_json::json!([{"apiKey": []}]));
    let schemes = &spec["components"]["securitySchemes"];
    for scheme in ["apiKey", "workerToken"] {
        assert_eq!(schemes[scheme]["scheme"], "bearer", "{scheme}");
    }
    let mut ids = BTreeSet::new();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let at = format!("{method} {path}");
            let id = op["operationId"]
                .as_str()
                .unwrap_or_else(|| panic!("{at}: no id"));
            assert!(ids.insert(id.to_string()), "{at}: operationId {id} twice");
            assert!(
                op["summary"].as_str().is_some_and(|s| !s.is_empty()),
                "{at}"
            );
            if path.starts_with("/internal/") {
                assert_eq!(
                    op["security"],
                    serde_json::json!([{"workerToken": []}]),
                    "{at}"
                );
                assert!(op["responses"].get("401").is_some(), "{at}");
            } else if path.starts_with("/v1/") {
                assert!(
                    op.get("security").is_none(),
                    "{at}: the API key is the default"
                );
                assert!(op["responses"].get("401").is_some(), "{at}");
            } else {
                assert_eq!(op["security"], serde_json::json!([]), "{at}");
            }
            // What the router answers before the handler (schemathesis found
            // 415 and 422 undocumented on the worker API's JSON bodies).
            if op["requestBody"]["content"]
                .get("application/json")
                .is_some()
            {
                for status in ["400", "415", "422"] {
                    assert!(op["responses"].get(status).is_some(), "{at}: {status}");
                }
            }
            for (status, response) in op["responses"].as_object().unwrap() {
                if status.starts_with('4') {
                    assert_eq!(
                        response["$ref"], "#/components/responses/Problem",
                        "{at}: {status}"
                    );
                }
            }
        }
    }
    // Every `$ref` names a component that exists.
    let text = spec.to_string();
    for reference in text.split("\"$ref\":\"").skip(1) {
        let reference = reference.split('"').next().unwrap();
        let pointer = reference.trim_start_matches('#');
        assert!(spec.pointer(pointer).is_some(), "{reference} is missing");
    }
    assert_eq!(
        spec["components"]["responses"]["Problem"]["content"]["application/problem+json"]["schema"]
            ["$ref"],
        "#/components/schemas/Problem"
    );
    app.cleanup().await;
}
