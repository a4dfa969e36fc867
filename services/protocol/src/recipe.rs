//! Recipes, outputs and manifests, shared with the CLI through the synth crate.

use serde_json::Value;

/// Why a recipe was refused, with the field it is about when known.
#[derive(Debug, Clone, PartialEq)]
pub struct RecipeError {
    pub field: Option<String>,
    pub message: String,
}

/// Parses and validates a recipe given as JSON (the CLI's TOML structure).
pub fn parse(value: &Value) -> Result<synth::Recipe, RecipeError> {
    synth::Recipe::from_value(value.clone()).map_err(|e| match e {
        synth::SynthError::Recipe { location, message } => RecipeError {
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

/// The files of one output, named and encoded as `motionaug augment` writes them:
/// `<name>.bvh` and `<name>.npz` (with the occlusion mask as a `mask` array,
/// bool [T, J], true = visible), and its manifest entry.
pub fn output_files(
    generated: &synth::Generated,
    source: &str,
) -> Result<(Vec<NamedFile>, synth::ManifestEntry), std::io::Error> {
    let motion = &generated.output.motion;
    let bvh_name = format!("{}.bvh", generated.name);
    let npz_name = format!("{}.npz", generated.name);
    let mut extras = Vec::new();
    if let Some(mask) = &generated.output.mask {
        let visible: Vec<bool> = mask.rows().into_iter().flatten().collect();
        extras.push(motion::npz::NpyArray::bool(
            "mask",
            &[motion.frames(), motion.joints()],
            &visible,
        )?);
    }
    let files = vec![
        (bvh_name.clone(), motion::bvh::to_bytes(motion)),
        (npz_name, motion::npz::motion_to_bytes(motion, &extras)?),
    ];
    Ok((files, generated.manifest_entry(bvh_name, source)))
}

/// `manifest.json` from the entries of every output: sorted by (source, op index,
/// copy) and pretty-printed with a final newline, exactly as the CLI writes it.
pub fn manifest_json(entries: Vec<Value>) -> Result<String, serde_json::Error> {
    let mut entries: Vec<synth::ManifestEntry> = entries
        .into_iter()
        .map(serde_json::from_value)
        .collect::<Result<_, _>>()?;
    entries.sort_by(|a, b| {
        (a.source.as_str(), a.op_index, a.copy).cmp(&(b.source.as_str(), b.op_index, b.copy))
    });
    let mut text = serde_json::to_string_pretty(&entries)?;
    text.push('\n');
    Ok(text)
}
