//! Folders as zips: a correction's PPO checkpoint and the debiasing model
//! travel between workers as one artifact each.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use pipeline::PipelineError;

fn io_error(path: &Path, source: std::io::Error) -> PipelineError {
    PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The newest complete PPO checkpoint under `dir` as a zip of its folder.
pub(crate) fn latest_checkpoint_zip(dir: &Path) -> Result<Option<Vec<u8>>, PipelineError> {
    let Some(latest) = ppo::latest_checkpoint(dir).map_err(correct::CorrectError::from)? else {
        return Ok(None);
    };
    let name = latest
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    zip_files(&latest, &format!("{name}/")).map(Some)
}

/// The files of `dir` (not recursive) as a zip.
pub(crate) fn zip_dir(dir: &Path) -> Result<Vec<u8>, PipelineError> {
    zip_files(dir, "")
}

fn zip_files(dir: &Path, prefix: &str) -> Result<Vec<u8>, PipelineError> {
    let zip_err = |e: zip::result::ZipError| PipelineError::Job(format!("zip: {e}"));
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| io_error(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    entries.sort();
    for path in entries {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let bytes = std::fs::read(&path).map_err(|e| io_error(&path, e))?;
        zip.start_file(format!("{prefix}{name}"), options)
            .map_err(zip_err)?;
        zip.write_all(&bytes).map_err(|e| io_error(&path, e))?;
    }
    Ok(zip.finish().map_err(zip_err)?.into_inner())
}

/// Unpacks a zip made by [`zip_files`] into `dir` (entries with `..` or
/// absolute paths are refused).
pub(crate) fn unzip_into(bytes: &[u8], dir: &Path) -> Result<(), PipelineError> {
    let zip_err = |e: zip::result::ZipError| PipelineError::Job(format!("zip: {e}"));
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(zip_err)?;
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).map_err(zip_err)?;
        let relative = entry
            .enclosed_name()
            .ok_or_else(|| PipelineError::Job("zip: an entry leaves its folder".into()))?;
        let path = dir.join(relative);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| io_error(parent, e))?;
        }
        let mut content = Vec::new();
        entry
            .read_to_end(&mut content)
            .map_err(|e| io_error(&path, e))?;
        std::fs::write(&path, content).map_err(|e| io_error(&path, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_survive_zipping() {
        let root = std::env::temp_dir().join(format!("motionaug-zip-{}", uuid::Uuid::new_v4()));
        let ckpt = root.join("a").join("ckpt-00000003-0000000000001");
        std::fs::create_dir_all(&ckpt).unwrap();
        std::fs::write(ckpt.join("state.json"), b"{}").unwrap();
        std::fs::write(ckpt.join("tensors.safetensors"), [1u8, 2, 3]).unwrap();
        let zipped = zip_files(&ckpt, "ckpt-00000003-0000000000001/").unwrap();
        let out = root.join("b");
        unzip_into(&zipped, &out).unwrap();
        let back = out.join("ckpt-00000003-0000000000001");
        assert_eq!(std::fs::read(back.join("state.json")).unwrap(), b"{}");
        assert_eq!(
            std::fs::read(back.join("tensors.safetensors")).unwrap(),
            [1, 2, 3]
        );
        assert!(unzip_into(b"not a zip", &out).is_err());
        std::fs::remove_dir_all(root).unwrap();
    }
}
