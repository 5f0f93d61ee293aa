//! Atomic file writes, the one routine every writer of the crate uses (outputs, sidecars,
//! tables, the service's table store): write a temporary file in the target's directory,
//! fsync it, rename it over the target, then fsync the directory so that the rename itself
//! survives a crash.

use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::error::{IoError, IoResult};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The ending of every temporary file [`write_atomic`] writes (`.<name>.<pid>-<n>.tmp`).
pub(crate) const TEMP_SUFFIX: &str = ".tmp";

/// A temporary sibling path of `path` that no other writer in this process uses.
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".to_string());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{}-{n}{TEMP_SUFFIX}", std::process::id()))
}

/// Whether `file_name` is a temporary file [`write_atomic`] writes for a target named
/// `<anything><target_suffix>`: one a crash between write and rename leaves behind.
pub(crate) fn is_temp_of(file_name: &str, target_suffix: &str) -> bool {
    file_name.starts_with('.')
        && file_name.ends_with(TEMP_SUFFIX)
        && file_name.contains(&format!("{target_suffix}."))
}

/// Writes `path` atomically: `fill` writes the content into a buffered temporary file in the
/// same directory, which is flushed, synced and renamed over `path`; the directory is synced
/// after the rename. On any error before the rename the temporary file is removed and `path`
/// is left untouched.
pub(crate) fn write_atomic<F>(path: &Path, fill: F) -> IoResult<()>
where
    F: FnOnce(&mut BufWriter<File>) -> IoResult<()>,
{
    write_atomic_then(path, fill, || {})
}

/// [`write_atomic`], running `before_rename` once the temporary file is synced and before it
/// is renamed into place.
pub(crate) fn write_atomic_then<F, B>(path: &Path, fill: F, before_rename: B) -> IoResult<()>
where
    F: FnOnce(&mut BufWriter<File>) -> IoResult<()>,
    B: FnOnce(),
{
    let tmp = temp_path(path);
    let result = (|| {
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| IoError::file("create", &tmp, e))?;
        let mut w = BufWriter::with_capacity(1 << 20, file);
        fill(&mut w)?;
        w.flush().map_err(|e| IoError::file("write", &tmp, e))?;
        let file = w
            .into_inner()
            .map_err(|e| IoError::file("write", &tmp, e.into_error()))?;
        file.sync_all()
            .map_err(|e| IoError::file("sync", &tmp, e))?;
        drop(file);
        before_rename();
        fs::rename(&tmp, path).map_err(|e| IoError::file("rename into", path, e))
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(|e| IoError::file("sync the directory of", path, e))
}

/// Writes `bytes` to `path` atomically.
pub(crate) fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> IoResult<()> {
    write_bytes_atomic_then(path, bytes, || {})
}

/// [`write_bytes_atomic`] with [`write_atomic_then`]'s `before_rename`.
pub(crate) fn write_bytes_atomic_then(
    path: &Path,
    bytes: &[u8],
    before_rename: impl FnOnce(),
) -> IoResult<()> {
    write_atomic_then(
        path,
        |w| {
            w.write_all(bytes)
                .map_err(|e| IoError::file("write", path, e))
        },
        before_rename,
    )
}

/// Reads a whole file, refusing files larger than `max_bytes` before reading them.
pub(crate) fn read_capped(path: &Path, max_bytes: u64) -> IoResult<Vec<u8>> {
    let len = fs::metadata(path)
        .map_err(|e| IoError::file("read", path, e))?
        .len();
    if len > max_bytes {
        return Err(IoError::Length {
            what: format!("file {}", path.display()),
            unit: "bytes",
            actual: usize::try_from(len).unwrap_or(usize::MAX),
            formula: "at most the size limit".to_string(),
            expected: u128::from(max_bytes),
        });
    }
    fs::read(path).map_err(|e| IoError::file("read", path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_fill_leaves_target_and_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.bin");
        write_bytes_atomic(&p, b"old").unwrap();
        let r = write_atomic(&p, |w| {
            w.write_all(b"partial").unwrap();
            Err(IoError::InvalidMeta("boom".into()))
        });
        assert!(r.is_err());
        assert_eq!(fs::read(&p).unwrap(), b"old");
        let names: Vec<_> = fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "temporary file left behind");
    }

    #[test]
    fn temporary_files_are_recognised_by_their_target() {
        let dir = tempfile::tempdir().unwrap();
        let tmp = temp_path(&dir.path().join("tbl_1.safetensors"));
        let name = tmp.file_name().unwrap().to_string_lossy().into_owned();
        assert!(is_temp_of(&name, ".safetensors"), "{name}");
        assert!(!is_temp_of("tbl_1.safetensors", ".safetensors"));
        assert!(!is_temp_of(&name, ".png"));
    }

    #[test]
    fn read_capped_refuses_big_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.bin");
        write_bytes_atomic(&p, &[0u8; 100]).unwrap();
        assert_eq!(read_capped(&p, 100).unwrap().len(), 100);
        let e = read_capped(&p, 99).unwrap_err().to_string();
        assert!(e.contains("has 100 bytes"), "{e}");
    }
}
