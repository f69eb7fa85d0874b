//! Writing files so that a crash, a full disk or a mistaken output path never leaves a
//! half-written file, a half-replaced folder or a user's file overwritten: every writer of
//! the workspace goes through here.

use std::io::Write;
use std::path::Path;

use crate::FileError;

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so a
/// crash or a full disk never leaves a half-written file under the final name.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let tmp = write_temporary(path, bytes)?;
    if let Err(e) = std::fs::rename(&tmp, path) {
        let _ = std::fs::remove_file(&tmp);
        return Err(FileError::io(path, e));
    }
    Ok(())
}

/// Writes `bytes` to a hidden temporary file beside `path` (`.NAME.tmpPID`, synced) and
/// returns it; the caller renames it into place. Temporaries of `path` left by a writer that
/// was killed (their process is gone) are removed first.
fn write_temporary(path: &Path, bytes: &[u8]) -> Result<std::path::PathBuf, FileError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(|e| FileError::io(&dir, e))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    remove_dead_writers_temporaries(&dir, &name);
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(FileError::io(path, e));
    }
    Ok(tmp)
}

/// Removes `dir/.NAME.tmpPID` files whose process no longer runs (a writer killed before
/// its rename), in any folder (unlike [`remove_stale_temporaries`], for folders of ours, it
/// takes only one name's and only a dead process's). Only where processes can be looked up
/// (`/proc`); elsewhere nothing is removed.
fn remove_dead_writers_temporaries(dir: &Path, name: &str) {
    let proc = Path::new("/proc/self");
    if !proc.exists() {
        return;
    }
    let prefix = format!(".{name}.tmp");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = file.strip_prefix(&prefix) else {
            continue;
        };
        let alive = Path::new("/proc").join(pid).exists();
        if !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()) && !alive {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Refuses `path` as an output unless it is missing or already a file of the kind about to
/// be written, whose first bytes are `magic` (`b"glTF"`, PNG's signature, [`WRITTEN_BY`]):
/// an existing file of another kind, given as the output by mistake, is left alone.
///
/// # Errors
/// [`FileError::Refused`] naming the path and what it is not; an I/O error reading it.
pub fn check_replaceable(path: &Path, magic: &[u8], kind: &str) -> Result<(), FileError> {
    if path.is_dir() {
        return Err(FileError::refused(
            path,
            format!("is a folder, not a {kind} file"),
        ));
    }
    if !path.exists() {
        return Ok(());
    }
    let mut head = vec![0u8; magic.len()];
    let read = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .map_err(|e| FileError::io(path, e))?;
    if read < magic.len() || head != magic {
        return Err(FileError::refused(
            path,
            format!(
                "exists and is not a {kind} file written by this tool; it was left untouched \
             (choose another output name)"
            ),
        ));
    }
    Ok(())
}

/// Writes a folder of `files` (name, bytes) as a whole: into a temporary sibling folder,
/// then renamed to `dir`, so a crash never leaves a folder with some files new and some
/// missing. An existing `dir` is replaced only when `replaceable` says it is an earlier
/// output of the same kind (it is moved aside first and removed after); any other existing
/// path is refused and left untouched.
///
/// # Errors
/// [`FileError::Refused`] for an existing `dir` that is a file or not `replaceable`; an
/// I/O error naming the path.
pub fn write_folder_atomically(
    dir: &Path,
    files: &[(String, Vec<u8>)],
    replaceable: impl Fn(&Path) -> bool,
) -> Result<(), FileError> {
    if dir.is_file() {
        return Err(FileError::refused(dir, "is a file; give a folder"));
    }
    let exists = dir.is_dir();
    let empty = exists
        && std::fs::read_dir(dir)
            .map_err(|e| FileError::io(dir, e))?
            .next()
            .is_none();
    if exists && !empty && !replaceable(dir) {
        return Err(FileError::refused(
            dir,
            "a folder that is not an earlier output of this command; give a new or empty \
             folder (nothing was written)",
        ));
    }
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| FileError::refused(dir, "not a folder name"))?;
    let parent = match dir.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| FileError::io(&parent, e))?;
    let pid = std::process::id();
    let partial = parent.join(format!(".{name}.partial{pid}"));
    let old = parent.join(format!(".{name}.old{pid}"));
    let write_all = || -> std::io::Result<()> {
        std::fs::create_dir_all(&partial)?;
        for (file, bytes) in files {
            let mut f = std::fs::File::create(partial.join(file))?;
            f.write_all(bytes)?;
            f.sync_all()?;
        }
        Ok(())
    };
    if let Err(e) = write_all() {
        let _ = std::fs::remove_dir_all(&partial);
        return Err(FileError::io(&partial, e));
    }
    if exists {
        std::fs::rename(dir, &old).map_err(|e| FileError::io(dir, e))?;
    }
    if let Err(e) = std::fs::rename(&partial, dir) {
        if exists {
            let _ = std::fs::rename(&old, dir);
        }
        let _ = std::fs::remove_dir_all(&partial);
        return Err(FileError::io(dir, e));
    }
    if exists {
        std::fs::remove_dir_all(&old).map_err(|e| FileError::io(&old, e))?;
    }
    Ok(())
}

/// Removes the temporaries [`write_atomically`] leaves in `dir` when a process is killed
/// mid-write (`.NAME.tmpPID` of another process than this one); returns what it removed.
/// Only for folders of ours (a run folder): nothing else matches the pattern.
///
/// # Errors
/// An unreadable folder or a temporary that cannot be removed.
pub fn remove_stale_temporaries(dir: &Path) -> Result<Vec<std::path::PathBuf>, FileError> {
    let own = format!(".tmp{}", std::process::id());
    let mut removed = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| FileError::io(dir, e))? {
        let entry = entry.map_err(|e| FileError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let stale = name.starts_with('.')
            && name.rsplit_once(".tmp").is_some_and(|(stem, pid)| {
                stem.len() > 1 && !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit())
            })
            && !name.ends_with(&own)
            && entry.file_type().is_ok_and(|t| t.is_file());
        if stale {
            let path = entry.path();
            std::fs::remove_file(&path).map_err(|e| FileError::io(&path, e))?;
            removed.push(path);
        }
    }
    Ok(removed)
}

/// Writes `files` (path, bytes) so that they appear together: all to temporary files first
/// (nothing renamed if one fails, the temporaries removed), then renamed in order.
pub fn write_all_or_none(files: &[(std::path::PathBuf, Vec<u8>)]) -> Result<(), FileError> {
    let mut temporaries = Vec::new();
    for (p, bytes) in files {
        match write_temporary(p, bytes) {
            Ok(t) => temporaries.push(t),
            Err(e) => {
                for t in &temporaries {
                    let _ = std::fs::remove_file(t);
                }
                return Err(e);
            }
        }
    }
    for (k, ((p, _), t)) in files.iter().zip(&temporaries).enumerate() {
        if let Err(e) = std::fs::rename(t, p) {
            for t in &temporaries[k..] {
                let _ = std::fs::remove_file(t);
            }
            return Err(FileError::io(p, e));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_replace_only_files_of_their_kind() {
        let tmp = std::env::temp_dir().join(format!("bitt-replace-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir_all(&tmp).unwrap();
        let (glb, notes) = (tmp.join("a.glb"), tmp.join("notes.glb"));
        check_replaceable(&glb, b"glTF", "glTF").unwrap();
        std::fs::write(&glb, b"glTF\x02\0\0\0").unwrap();
        check_replaceable(&glb, b"glTF", "glTF").unwrap();
        std::fs::write(&notes, b"my notes").unwrap();
        let e = check_replaceable(&notes, b"glTF", "glTF")
            .unwrap_err()
            .to_string();
        assert!(e.contains("notes.glb") && e.contains("untouched"), "{e}");
        std::fs::write(&notes, b"gl").unwrap();
        assert!(
            check_replaceable(&notes, b"glTF", "glTF").is_err(),
            "shorter than the magic"
        );
        assert!(
            check_replaceable(&tmp, b"glTF", "glTF").is_err(),
            "a folder"
        );
        std::fs::remove_dir_all(&tmp).unwrap();
    }

    #[test]
    fn folders_are_written_whole_and_foreign_folders_refused() {
        let tmp = std::env::temp_dir().join(format!("bitt-folder-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        let dir = tmp.join("out");
        let files = |x: &str| {
            vec![
                ("a.txt".to_string(), x.as_bytes().to_vec()),
                ("ours".to_string(), vec![]),
            ]
        };
        let ours = |d: &Path| d.join("ours").is_file();
        write_folder_atomically(&dir, &files("1"), ours).unwrap();
        assert_eq!(std::fs::read_to_string(dir.join("a.txt")).unwrap(), "1");
        write_folder_atomically(&dir, &files("2"), ours).unwrap();
        assert_eq!(std::fs::read_to_string(dir.join("a.txt")).unwrap(), "2");
        // Nothing else is left beside it.
        assert_eq!(std::fs::read_dir(&tmp).unwrap().count(), 1);
        // A foreign folder and a file are refused untouched.
        let foreign = tmp.join("foreign");
        std::fs::create_dir_all(&foreign).unwrap();
        std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
        let e = write_folder_atomically(&foreign, &files("3"), ours).unwrap_err();
        assert!(e.to_string().contains("not an earlier output"), "{e}");
        assert_eq!(
            std::fs::read_to_string(foreign.join("notes.txt")).unwrap(),
            "mine"
        );
        assert!(!foreign.join("a.txt").exists());
        let file = tmp.join("file.glb");
        std::fs::write(&file, "x").unwrap();
        assert!(write_folder_atomically(&file, &files("4"), ours).is_err());
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "x");
        std::fs::remove_dir_all(&tmp).unwrap();
    }

    #[test]
    fn atomic_write_replaces_whole_file() {
        let dir = std::env::temp_dir().join(format!("bitt-atomic-{}", std::process::id()));
        let path = dir.join("x.txt");
        write_atomically(&path, b"first").unwrap();
        write_atomically(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        let leftovers = std::fs::read_dir(&dir).unwrap().count();
        assert_eq!(leftovers, 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
