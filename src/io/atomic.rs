//! Atomic file writes: write a temporary file in the target's directory, then rename it.

use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::error::{IoError, IoResult};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A temporary sibling path of `path` that no other writer in this process uses.
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".to_string());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.tmp-{}-{n}", std::process::id()))
}

/// Writes `path` atomically: `fill` writes the content into a buffered temporary file in the
/// same directory, which is flushed, synced and renamed over `path`. On any error the temporary
/// file is removed and `path` is left untouched.
pub(crate) fn write_atomic<F>(path: &Path, fill: F) -> IoResult<()>
where
    F: FnOnce(&mut BufWriter<File>) -> IoResult<()>,
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
        fs::rename(&tmp, path).map_err(|e| IoError::file("rename into", path, e))
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically.
pub(crate) fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> IoResult<()> {
    write_atomic(path, |w| {
        w.write_all(bytes)
            .map_err(|e| IoError::file("write", path, e))
    })
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
    fn read_capped_refuses_big_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.bin");
        write_bytes_atomic(&p, &[0u8; 100]).unwrap();
        assert_eq!(read_capped(&p, 100).unwrap().len(), 100);
        let e = read_capped(&p, 99).unwrap_err().to_string();
        assert!(e.contains("has 100 bytes"), "{e}");
    }
}
