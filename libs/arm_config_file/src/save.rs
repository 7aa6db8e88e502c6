//! The file: a configuration rewritten by [`calibration_text`] and saved atomically,
//! the previous one kept as `<name>.bak`.

use crate::{calibration_text, WriteError};
use eezybot_kinematics::{
    ArmConfig, ConfigError, LeaderCalibration, ServoCalibrations, MAX_CONFIG_BYTES,
};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// Where [`write_calibration`] keeps the previous file: `<name>.bak` beside it (one
/// backup, replaced at each save).
pub fn backup_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".bak");
    path.with_file_name(name)
}

/// What [`write_calibration`] did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Saved {
    /// The configuration file written (symbolic links resolved).
    pub path: PathBuf,
    /// The previous file's copy.
    pub backup: PathBuf,
}

/// Rewrite the configuration file at `path` with a new servo calibration (and leader
/// section, if given), atomically: the new text ([`calibration_text`], verified before
/// anything is written) goes to a temporary file in the same directory, is flushed to
/// disk and loaded back, the previous file is copied to [`backup_path`] (flushed, then
/// renamed over the old backup), and the temporary file is renamed over `path`; the
/// directory is flushed last. On any error the configuration file is unchanged and the
/// temporary files are removed. A symbolic link is followed: the file it points to is
/// replaced, the link stays.
pub fn write_calibration(
    path: &Path,
    servos: &ServoCalibrations,
    leader: Option<&LeaderCalibration>,
) -> Result<Saved, WriteError> {
    let target = std::fs::canonicalize(path).map_err(|source| WriteError::Io {
        action: "cannot resolve",
        path: path.to_path_buf(),
        source,
    })?;
    let original = read_limited(&target)?;
    let text = calibration_text(&original, servos, leader)?;
    replace_atomically(&target, &original, &text)?;
    Ok(Saved {
        backup: backup_path(&target),
        path: target,
    })
}

fn read_limited(path: &Path) -> Result<String, WriteError> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_CONFIG_BYTES as u64 + 1).read_to_end(&mut bytes))
        .map_err(|source| WriteError::Io {
            action: "cannot read",
            path: path.to_path_buf(),
            source,
        })?;
    String::from_utf8(bytes).map_err(|e| {
        WriteError::Original(ConfigError::Read {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
        })
    })
}

/// Write `text` to a new file `dir/.<name>.<tag>.<pid>`, flushed; removed on error.
fn write_temp(
    target: &Path,
    tag: &str,
    text: &str,
    permissions: Option<std::fs::Permissions>,
) -> Result<PathBuf, WriteError> {
    let name = target.file_name().unwrap_or_default().to_string_lossy();
    let tmp = target.with_file_name(format!(".{name}.{tag}.{}", std::process::id()));
    let io = |action, source| WriteError::Io {
        action,
        path: tmp.clone(),
        source,
    };
    // a stale file from an earlier crash of a process with the same id
    let _ = std::fs::remove_file(&tmp);
    let write = || -> Result<(), WriteError> {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| io("cannot create", e))?;
        f.write_all(text.as_bytes())
            .map_err(|e| io("cannot write", e))?;
        if let Some(p) = permissions {
            f.set_permissions(p)
                .map_err(|e| io("cannot set the permissions of", e))?;
        }
        f.sync_all().map_err(|e| io("cannot flush", e))
    };
    match write() {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// The I/O part of [`write_calibration`]: `text` must load as an arm configuration
/// (checked again from the written bytes) before anything replaces `target`.
fn replace_atomically(target: &Path, original: &str, text: &str) -> Result<(), WriteError> {
    let expected = ArmConfig::from_yaml(text, "the rewritten configuration")
        .map_err(|e| WriteError::Verify(e.to_string()))?;
    let permissions = std::fs::metadata(target).ok().map(|m| m.permissions());
    let tmp = write_temp(target, "new", text, permissions.clone())?;
    let cleanup = |e: WriteError, files: &[&Path]| {
        for f in files {
            let _ = std::fs::remove_file(f);
        }
        e
    };
    match ArmConfig::load(&tmp) {
        Ok(back) if back == expected => {}
        Ok(_) => {
            return Err(cleanup(
                WriteError::Verify("the written file reads back differently".into()),
                &[tmp.as_path()],
            ))
        }
        Err(e) => return Err(cleanup(WriteError::Verify(e.to_string()), &[tmp.as_path()])),
    }
    let bak_tmp = write_temp(target, "bak", original, permissions)
        .map_err(|e| cleanup(e, &[tmp.as_path()]))?;
    let backup = backup_path(target);
    std::fs::rename(&bak_tmp, &backup).map_err(|source| {
        cleanup(
            WriteError::Io {
                action: "cannot keep the backup",
                path: backup.clone(),
                source,
            },
            &[tmp.as_path(), bak_tmp.as_path()],
        )
    })?;
    std::fs::rename(&tmp, target).map_err(|source| {
        cleanup(
            WriteError::Io {
                action: "cannot replace",
                path: target.to_path_buf(),
                source,
            },
            &[tmp.as_path()],
        )
    })?;
    if let Some(dir) = target.parent() {
        // make the renames durable; a directory that cannot be opened for this (some
        // platforms) is no error
        if let Ok(d) = std::fs::File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::odd_calibration;
    use eezybot_kinematics::SHIPPED_ARM_YAML;

    struct TempDir(PathBuf);
    impl TempDir {
        fn new(tag: &str) -> TempDir {
            let dir = std::env::temp_dir()
                .join(format!("eezybot_calibration_{tag}_{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }
        fn files(&self) -> Vec<String> {
            let mut v: Vec<String> = std::fs::read_dir(&self.0)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        }
    }
    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn write_calibration_is_atomic_and_keeps_a_backup() {
        let dir = TempDir::new("write");
        let path = dir.0.join("arm.yaml");
        std::fs::write(&path, SHIPPED_ARM_YAML).unwrap();
        let new = odd_calibration();
        let saved = write_calibration(&path, &new, None).unwrap();
        assert_eq!(saved.backup, dir.0.join("arm.yaml.bak"));
        assert_eq!(ArmConfig::load(&path).unwrap().servos, new);
        assert_eq!(
            std::fs::read_to_string(&saved.backup).unwrap(),
            SHIPPED_ARM_YAML
        );
        assert_eq!(dir.files(), ["arm.yaml", "arm.yaml.bak"]);
        // the second save replaces the backup with the first save's file
        let first = std::fs::read_to_string(&path).unwrap();
        write_calibration(&path, &ServoCalibrations::default(), None).unwrap();
        assert_eq!(std::fs::read_to_string(&saved.backup).unwrap(), first);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), SHIPPED_ARM_YAML);
        assert_eq!(dir.files(), ["arm.yaml", "arm.yaml.bak"]);
    }

    #[cfg(unix)]
    #[test]
    fn write_calibration_follows_a_symlink_and_keeps_permissions() {
        use std::os::unix::fs::PermissionsExt;
        let dir = TempDir::new("link");
        let real = dir.0.join("real.yaml");
        std::fs::write(&real, SHIPPED_ARM_YAML).unwrap();
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o640)).unwrap();
        let link = dir.0.join("arm.yaml");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let saved = write_calibration(&link, &odd_calibration(), None).unwrap();
        assert_eq!(saved.path, std::fs::canonicalize(&real).unwrap());
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(ArmConfig::load(&link).unwrap().servos, odd_calibration());
        assert_eq!(
            std::fs::metadata(&real).unwrap().permissions().mode() & 0o777,
            0o640
        );
    }

    #[test]
    fn a_failed_write_leaves_the_original_untouched() {
        let dir = TempDir::new("fail");
        let path = dir.0.join("arm.yaml");
        std::fs::write(&path, SHIPPED_ARM_YAML).unwrap();
        // new text that would not load: refused before anything is written
        let err = replace_atomically(&path, SHIPPED_ARM_YAML, "servos: { base: nonsense }\n")
            .unwrap_err();
        assert!(matches!(err, WriteError::Verify(_)), "{err}");
        // an invalid calibration, and an original that does not load
        let mut bad = ServoCalibrations::default();
        bad.shoulder.max_deg = 181.0;
        assert!(matches!(
            write_calibration(&path, &bad, None),
            Err(WriteError::Invalid(_))
        ));
        assert_eq!(std::fs::read_to_string(&path).unwrap(), SHIPPED_ARM_YAML);
        assert_eq!(dir.files(), ["arm.yaml"]);
        let broken = dir.0.join("broken.yaml");
        std::fs::write(&broken, "geometry: { nonsense: 1 }\n").unwrap();
        assert!(matches!(
            write_calibration(&broken, &ServoCalibrations::default(), None),
            Err(WriteError::Original(_))
        ));
        assert_eq!(
            std::fs::read_to_string(&broken).unwrap(),
            "geometry: { nonsense: 1 }\n"
        );
        assert!(matches!(
            write_calibration(
                &dir.0.join("missing.yaml"),
                &ServoCalibrations::default(),
                None
            ),
            Err(WriteError::Io { .. })
        ));
        assert_eq!(dir.files(), ["arm.yaml", "broken.yaml"]);
    }
}
