//! Recipes and manifests, shared with the CLI through the pipeline crate.

use serde_json::Value;

/// Why a recipe was refused, with the table or field it is about when known.
#[derive(Debug, Clone, PartialEq)]
pub struct RecipeError {
    pub field: Option<String>,
    pub message: String,
}

/// Parses and validates a recipe given as JSON (the CLI's TOML structure:
/// `[[ops]]`, `[vae]`, `[interaction]`, `[correct]`, `[debias]`).
pub fn parse(value: &Value) -> Result<pipeline::Recipe, RecipeError> {
    pipeline::Recipe::from_value(value.clone()).map_err(|e| match e {
        pipeline::PipelineError::Recipe { location, message } => RecipeError {
            message: format!("{location}: {message}"),
            field: Some(location),
        },
        other => RecipeError {
            field: None,
            message: other.to_string(),
        },
    })
}

/// A result file: name and bytes.
pub type NamedFile = (String, Vec<u8>);

/// `manifest.json` from the entries of every output (`pipeline::ManifestEntry`
/// as JSON): sorted and pretty-printed with a final newline, exactly as
/// `motionaug augment` writes it.
pub fn manifest_json(entries: Vec<Value>) -> Result<String, serde_json::Error> {
    let mut entries: Vec<pipeline::ManifestEntry> = entries
        .into_iter()
        .map(serde_json::from_value)
        .collect::<Result<_, _>>()?;
    pipeline::manifest::sort(&mut entries);
    let mut text = serde_json::to_string_pretty(&entries)?;
    text.push('\n');
    Ok(text)
}
