//! The OpenAPI document served at `/openapi.json`.
//!
//! Every operation is described by the `#[utoipa::path]` attribute on its handler
//! and registered with the router through `utoipa_axum::routes!`, so the routes and
//! the document come from one place ([`crate::routes::router`]). This module holds
//! what no handler carries: the document's info, the two bearer schemes, the
//! `application/problem+json` error response, schemas for bodies that have no Rust
//! type of ours (raw bytes, the recipe) and for the worker API's wire types, which
//! live in `motionaug_protocol` (a crate without utoipa).

use axum::body::Bytes;
use serde_json::{Value, json};
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::openapi::{KnownFormat, ObjectBuilder, Ref, RefOr, Schema, SchemaFormat, Type};
use utoipa::{Modify, OpenApi, PartialSchema, ToSchema};

use crate::error::Problem;

const DESCRIPTION: &str = "Upload motion-capture datasets, augment them with a recipe, \
follow progress and download the results. All /v1 routes need `Authorization: Bearer <api key>`; \
errors are application/problem+json. Every limit, recipe bound and tenant quota in force, \
with the tenant's use, is at GET /v1/limits; a refused quota is named in the problem's `limit`.";

#[derive(OpenApi)]
#[openapi(
    info(title = "motionaug service", description = DESCRIPTION),
    security(("apiKey" = [])),
    components(schemas(Problem), responses(Problem)),
    modifiers(&BearerSchemes)
)]
struct ApiDoc;

/// `apiKey` (the default of every operation) and `workerToken` (`/internal/v1`).
struct BearerSchemes;

impl Modify for BearerSchemes {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        let bearer = |description: &str| {
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some(description))
                    .build(),
            )
        };
        components.add_security_scheme(
            "apiKey",
            bearer("Tenant API key from `motionaug-coordinator create-key --tenant NAME`"),
        );
        components.add_security_scheme("workerToken", bearer("MOTIONAUG_WORKER_TOKEN"));
    }
}

/// The document's frame (info, security, shared components) that the router adds
/// its operations to.
pub fn base() -> utoipa::openapi::OpenApi {
    ApiDoc::openapi()
}

/// How a route's path is written in the document: axum's wildcard segment
/// `{*name}` is the OpenAPI path parameter `{name}`.
pub fn spec_path(route: &str) -> String {
    route.replace("{*", "{")
}

/// The document the router collected, with its paths written the OpenAPI way,
/// a 400 problem on every operation that reads a path, a query or a body
/// (what the router answers when one of them cannot be read), and 415 and 422
/// problems on every operation with a JSON body (no JSON content type; JSON
/// that does not match the body's type).
pub fn finish(mut api: utoipa::openapi::OpenApi) -> utoipa::openapi::OpenApi {
    api.paths.paths = std::mem::take(&mut api.paths.paths)
        .into_iter()
        .map(|(path, mut item)| {
            for op in [
                &mut item.get,
                &mut item.put,
                &mut item.post,
                &mut item.delete,
                &mut item.patch,
            ]
            .into_iter()
            .flatten()
            {
                let reads_input = op.request_body.is_some()
                    || op.parameters.as_ref().is_some_and(|p| !p.is_empty());
                let json_body = matches!(
                    &op.request_body,
                    Some(RefOr::T(body)) if body.content.contains_key("application/json")
                );
                let statuses: &[&str] = match (reads_input, json_body) {
                    (_, true) => &["400", "415", "422"],
                    (true, false) => &["400"],
                    (false, false) => &[],
                };
                for status in statuses {
                    op.responses
                        .responses
                        .entry(status.to_string())
                        .or_insert_with(|| Ref::from_response_name("Problem").into());
                }
            }
            (spec_path(&path), item)
        })
        .collect();
    api
}

/// The finished document as JSON, shared by the `/openapi.json` handler.
#[derive(Clone)]
pub struct OpenApiJson(pub Bytes);

impl OpenApiJson {
    pub fn new(api: &utoipa::openapi::OpenApi) -> Self {
        // A document of plain data always serialises.
        let text = api.to_pretty_json().unwrap_or_default();
        OpenApiJson(Bytes::from(text))
    }
}

/// Raw bytes: a file or a checkpoint (`type: string, format: binary`).
pub struct Binary;

impl PartialSchema for Binary {
    fn schema() -> RefOr<Schema> {
        ObjectBuilder::new()
            .schema_type(Type::String)
            .format(Some(SchemaFormat::KnownFormat(KnownFormat::Binary)))
            .into()
    }
}

impl ToSchema for Binary {}

/// The multipart body of an upload.
pub struct DatasetUpload;

impl PartialSchema for DatasetUpload {
    fn schema() -> RefOr<Schema> {
        schema_from_json(json!({
            "type": "object",
            "properties": {
                "file": {
                    "type": "array",
                    "items": {"type": "string", "format": "binary"},
                    "description": "BVH, ASF, AMC files, NPZ clips motionaug wrote, or zips of them; \
                        AMC motions pair with \
                        an ASF of the same upload (the only one, or the one whose name is the \
                        longest prefix of the AMC's name)"
                },
                "name": {"type": "string", "description": "The dataset's name (default: the first file's name)"}
            },
            "required": ["file"]
        }))
    }
}

impl ToSchema for DatasetUpload {}

/// The recipe: parsed at run time by the pipeline crate, so described here.
pub struct Recipe;

impl PartialSchema for Recipe {
    fn schema() -> RefOr<Schema> {
        schema_from_json(json!({
            "type": "object",
            "description": "The CLI's recipe as JSON (pipeline::Recipe): {\"seed\": 7, \"ops\": \
                [{\"op\": \"noise\", \"copies\": 3, ...op parameters}], \"vae\": {...}, \
                \"interaction\": {...}, \"correct\": {...}, \"debias\": {...}}. op is one of the \
                synth crate's ops (noise, time_warp, mirror, mask, ...); the tables are those of \
                the pipeline crate's recipe module (unknown fields are refused, naming the table).",
            "properties": {
                "seed": {"type": "integer", "minimum": 0},
                "ops": {
                    "type": "array",
                    "items": {
                        "type": "object",
                        "properties": {
                            "op": {"type": "string"},
                            "copies": {"type": "integer", "minimum": 1, "maximum": 1000}
                        },
                        "required": ["op"],
                        "additionalProperties": true
                    }
                },
                "vae": {"type": "object"},
                "interaction": {"type": "object"},
                "correct": {"type": "object"},
                "debias": {"type": "object"}
            }
        }))
    }
}

impl ToSchema for Recipe {}

/// A schema written as JSON; the literals above are checked by the unit tests.
fn schema_from_json(value: Value) -> RefOr<Schema> {
    serde_json::from_value(value).unwrap_or_default()
}

/// Schemas of the worker API's bodies, mirroring `motionaug_protocol`'s types
/// field for field (the tests compare each with the real type). Never built:
/// they only describe the JSON.
pub mod wire {
    use serde_json::Value;
    use utoipa::ToSchema;
    use uuid::Uuid;

    /// Ask for one runnable job.
    #[derive(ToSchema)]
    pub struct ClaimRequest {
        /// Stable id of the worker process (shown in job listings and logs).
        pub worker_id: String,
        /// Job kinds this worker can run.
        pub kinds: Vec<String>,
        /// How long the coordinator may hold the request open waiting for work
        /// (long poll). The coordinator caps it.
        #[serde(default)]
        pub wait_ms: u64,
    }

    /// The job and the lease the worker now holds on it.
    #[derive(ToSchema)]
    pub struct ClaimedJob {
        pub id: Uuid,
        /// Lease token. Every claim of a job gets a new, larger epoch; every report
        /// about the job must carry it, and reports with an older epoch are rejected.
        pub epoch: i64,
        pub kind: String,
        /// 1 for the first run, 2 for the first retry, ...
        pub attempt: i32,
        /// Kind-specific input.
        #[schema(value_type = Object)]
        pub input: Value,
        /// The lease expires this long after the last heartbeat.
        pub lease_ms: u64,
        /// How often the worker should heartbeat.
        pub heartbeat_ms: u64,
        /// Whether a previous attempt stored a checkpoint.
        pub has_checkpoint: bool,
        /// The outputs of the jobs this one depends on (all succeeded).
        #[serde(default)]
        pub deps: Vec<DepOutput>,
    }

    /// A finished input of a claimed job.
    #[derive(ToSchema)]
    pub struct DepOutput {
        /// The dependency's key in the plan (`correct_original:walk`, ...).
        pub key: String,
        pub kind: String,
        /// Its job output.
        #[schema(value_type = Object)]
        pub output: Value,
    }

    /// Extend the lease, report progress.
    #[derive(ToSchema)]
    pub struct HeartbeatRequest {
        pub epoch: i64,
        /// Fraction done, 0..=1.
        #[schema(minimum = 0, maximum = 1)]
        pub progress: f64,
    }

    #[derive(ToSchema)]
    pub struct HeartbeatReply {
        /// The job was cancelled: stop working on it and report nothing more.
        pub cancelled: bool,
    }

    #[derive(ToSchema)]
    pub struct CompleteRequest {
        pub epoch: i64,
        /// The job's output: manifest entries and the artifacts it uploaded.
        #[schema(value_type = Object)]
        pub output: Value,
    }

    #[derive(ToSchema)]
    pub struct FailRequest {
        pub epoch: i64,
        /// What went wrong, for the user (kept on the job).
        pub error: String,
        /// `false` when running the job again cannot help (bad input).
        pub retryable: bool,
    }

    /// Give a job back without using up an attempt; its checkpoint is kept.
    #[derive(ToSchema)]
    pub struct ReleaseRequest {
        pub epoch: i64,
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use motionaug_protocol as protocol;
    use serde::Serialize;
    use serde::de::DeserializeOwned;
    use uuid::Uuid;

    use super::*;

    /// `M` describes `T`: the same properties, and exactly the required ones are
    /// needed to read a `T`.
    fn assert_mirrors<M: ToSchema, T: Serialize + DeserializeOwned>(sample: T) {
        let name = M::name();
        let schema = serde_json::to_value(M::schema()).unwrap();
        let properties: BTreeSet<&String> = schema["properties"]
            .as_object()
            .unwrap_or_else(|| panic!("{name}: {schema}"))
            .keys()
            .collect();
        let full = serde_json::to_value(&sample).unwrap();
        let fields: BTreeSet<&String> = full.as_object().unwrap().keys().collect();
        assert_eq!(properties, fields, "{name}");
        let required: Vec<&str> = schema["required"]
            .as_array()
            .map(|r| r.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        let minimal: serde_json::Map<String, Value> = full
            .as_object()
            .unwrap()
            .iter()
            .filter(|(k, _)| required.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        serde_json::from_value::<T>(Value::Object(minimal.clone()))
            .unwrap_or_else(|e| panic!("{name}: the required properties are not enough: {e}"));
        for field in &required {
            let mut without = minimal.clone();
            without.remove(*field);
            assert!(
                serde_json::from_value::<T>(Value::Object(without)).is_err(),
                "{name}: `{field}` is marked required but is optional"
            );
        }
    }

    #[test]
    fn wire_schemas_match_the_protocol() {
        assert_mirrors::<wire::ClaimRequest, _>(protocol::ClaimRequest {
            worker_id: "w".into(),
            kinds: vec!["synthesize".into()],
            wait_ms: 5,
        });
        let dep = protocol::DepOutput {
            key: "synthesize:walk".into(),
            kind: "synthesize".into(),
            output: json!({}),
        };
        assert_mirrors::<wire::DepOutput, _>(dep.clone());
        assert_mirrors::<wire::ClaimedJob, _>(protocol::ClaimedJob {
            id: Uuid::nil(),
            epoch: 1,
            kind: "synthesize".into(),
            attempt: 1,
            input: json!({}),
            lease_ms: 1000,
            heartbeat_ms: 250,
            has_checkpoint: false,
            deps: vec![dep],
        });
        assert_mirrors::<wire::HeartbeatRequest, _>(protocol::HeartbeatRequest {
            epoch: 1,
            progress: 0.5,
        });
        assert_mirrors::<wire::HeartbeatReply, _>(protocol::HeartbeatReply { cancelled: false });
        assert_mirrors::<wire::CompleteRequest, _>(protocol::CompleteRequest {
            epoch: 1,
            output: json!({}),
        });
        assert_mirrors::<wire::FailRequest, _>(protocol::FailRequest {
            epoch: 1,
            error: "boom".into(),
            retryable: true,
        });
        assert_mirrors::<wire::ReleaseRequest, _>(protocol::ReleaseRequest { epoch: 1 });
    }

    #[test]
    fn hand_written_schemas_are_valid() {
        for (name, schema) in [
            ("DatasetUpload", DatasetUpload::schema()),
            ("Recipe", Recipe::schema()),
        ] {
            let value = serde_json::to_value(schema).unwrap();
            assert_eq!(value["type"], "object", "{name}: {value}");
            assert!(value["properties"].as_object().is_some(), "{name}: {value}");
        }
        assert_eq!(
            serde_json::to_value(Binary::schema()).unwrap(),
            json!({"type": "string", "format": "binary"})
        );
    }

    #[test]
    fn wildcard_segments_become_path_parameters() {
        assert_eq!(
            spec_path("/internal/v1/jobs/{id}/artifacts/{*name}"),
            "/internal/v1/jobs/{id}/artifacts/{name}"
        );
        assert_eq!(spec_path("/v1/datasets/{id}"), "/v1/datasets/{id}");
    }
}
