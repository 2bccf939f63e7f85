use super::*;
use pavlov::learn::{Horde, SignalNames, TickSignals};

fn horde() -> Horde<f32> {
    let family: FamilySpec = toml::from_str(
        r#"
        name = "n"
        cumulants = ["obs/*", "bias"]
        taus = [2.0, 8.0]
        lambda = 0.9
        alpha = 0.01
        features = { kind = "one_dim", all_obs = true, tiles = 4, tilings = 2 }
    "#,
    )
    .unwrap();
    let names = SignalNames {
        obs: (0..5).map(|i| format!("d{i}")).collect(),
        extra: vec![],
        stimuli: vec!["stall".into()],
    };
    let mut h = Horde::new(vec![family], &names).unwrap();
    for t in 0..300 {
        let obs: Vec<f64> = (0..5).map(|d| ((t * (d + 1)) % 17) as f64 / 17.0).collect();
        h.step(&TickSignals {
            obs: &obs,
            raw: &obs,
            extra: &[],
            stimuli: &[t % 40 == 0],
        });
    }
    h
}

fn snapshot(h: &mut Horde<f32>) -> HordeSnapshot<f32> {
    assert!(h.begin_snapshot());
    assert!(h.advance_snapshot(usize::MAX));
    h.take_snapshot().unwrap()
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pavlov-horde-file-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn a_checkpoint_reads_back_exactly_and_restores_the_horde() {
    let mut h = horde();
    let snap = snapshot(&mut h);
    let d = dir("roundtrip");
    let path = write_atomic(&d, 1234, &snap).unwrap();
    assert_eq!(path.file_name().unwrap(), "horde-1234.bin");
    let (tick, back) = read::<f32>(&path).unwrap();
    assert_eq!((tick, &back), (1234, &snap));
    let mut fresh = Horde::<f32>::new(h.families().to_vec(), &{
        SignalNames {
            obs: (0..5).map(|i| format!("d{i}")).collect(),
            extra: vec![],
            stimuli: vec!["stall".into()],
        }
    })
    .unwrap();
    fresh.restore_snapshot(&back).unwrap();
    assert_eq!(fresh.state(), h.state());
    // Another precision is refused by name.
    assert!(matches!(
        read::<f64>(&path),
        Err(HordeFileError::Precision { .. })
    ));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn cut_corrupted_and_foreign_files_are_refused_precisely() {
    let mut h = horde();
    let snap = snapshot(&mut h);
    let d = dir("damaged");
    let path = write_atomic(&d, 7, &snap).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let bad = d.join("bad.bin");
    std::fs::write(&bad, &bytes[..bytes.len() - 100]).unwrap();
    assert!(matches!(read::<f32>(&bad), Err(HordeFileError::Truncated)));
    let mut flipped = bytes.clone();
    let k = flipped.len() - 50;
    flipped[k] ^= 0x40;
    std::fs::write(&bad, &flipped).unwrap();
    assert!(matches!(read::<f32>(&bad), Err(HordeFileError::Checksum)));
    std::fs::write(&bad, b"{\"not\": \"a horde\"}").unwrap();
    assert!(matches!(
        read::<f32>(&bad),
        Err(HordeFileError::NotAHordeFile)
    ));
    let mut version = bytes.clone();
    version[13] = 9;
    std::fs::write(&bad, &version).unwrap();
    assert!(matches!(read::<f32>(&bad), Err(HordeFileError::Version(9))));
    let mut huge = bytes;
    huge[17..25].copy_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(&bad, &huge).unwrap();
    assert!(matches!(read::<f32>(&bad), Err(HordeFileError::Header(_))));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_non_finite_weight_is_never_written_and_old_files_are_pruned() {
    let mut h = horde();
    let mut snap = snapshot(&mut h);
    let d = dir("prune");
    for tick in [10, 20, 30] {
        write_atomic(&d, tick, &snap).unwrap();
    }
    prune(&d, 2).unwrap();
    let mut left: Vec<String> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, vec!["horde-20.bin", "horde-30.bin"]);
    snap.groups[0].1[3] = f32::NAN;
    assert!(matches!(
        write_atomic(&d, 40, &snap),
        Err(HordeFileError::NonFinite)
    ));
    assert!(!d.join("horde-40.bin").exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_write_the_disk_refuses_leaves_no_temporary_file() {
    let mut h = horde();
    let snap = snapshot(&mut h);
    let d = dir("full");
    std::fs::create_dir_all(&d).unwrap();
    // The temporary file's name leads to /dev/full: every write to it fails with ENOSPC, as on a full disk.
    let tmp = d.join(format!(".{}.tmp", file_name(77)));
    std::os::unix::fs::symlink("/dev/full", &tmp).unwrap();
    let err = write_atomic(&d, 77, &snap).unwrap_err();
    assert!(
        matches!(&err, HordeFileError::Io(e) if e.raw_os_error() == Some(28)),
        "{err}"
    );
    assert!(
        std::fs::symlink_metadata(&tmp).is_err(),
        "the temporary file is left"
    );
    assert!(list(&d).unwrap().is_empty());
    // With room again, the same checkpoint is written.
    write_atomic(&d, 77, &snap).unwrap();
    let left: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(left, ["horde-77.bin"]);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn true_online_and_autostep_state_reads_back_exactly() {
    // A family of each new learner beside the paper's: V_old in the header, Autostep's step sizes, h
    // and v after its weights (four blocks per group).
    let mut families = horde().families().to_vec();
    for (name, learner) in [("dutch", "true_online"), ("auto", "autostep")] {
        let mut f = families[0].clone();
        f.name = name.into();
        f.learner = toml::from_str::<FamilySpec>(&format!(
            "name = \"x\"\ncumulants = [\"bias\"]\ntaus = [2.0]\nlambda = 0.9\nalpha = 0.01\n\
             learner = \"{learner}\"\nfeatures = {{ kind = \"one_dim\", all_obs = true, tiles = 4 }}"
        ))
        .unwrap()
        .learner;
        families.push(f);
    }
    let names = SignalNames {
        obs: (0..5).map(|i| format!("d{i}")).collect(),
        extra: vec![],
        stimuli: vec!["stall".into()],
    };
    let mut h = Horde::<f32>::new(families.clone(), &names).unwrap();
    for t in 0..300 {
        let obs: Vec<f64> = (0..5).map(|d| ((t * (d + 1)) % 17) as f64 / 17.0).collect();
        h.step(&TickSignals {
            obs: &obs,
            raw: &obs,
            extra: &[],
            stimuli: &[t % 40 == 0],
        });
    }
    let snap = snapshot(&mut h);
    assert!(snap.groups.iter().any(|(s, _)| s.dutch.is_some()));
    let (state, values) = snap.groups.iter().find(|(s, _)| s.autostep).unwrap();
    assert_eq!(values.len(), 4 * state.coef.len() * state.a.len());
    let d = dir("learners");
    let path = write_atomic(&d, 5, &snap).unwrap();
    let (_, back) = read::<f32>(&path).unwrap();
    assert_eq!(back, snap);
    let mut fresh = Horde::<f32>::new(families, &names).unwrap();
    fresh.restore_snapshot(&back).unwrap();
    assert_eq!(fresh.state(), h.state());
    let _ = std::fs::remove_dir_all(&d);
}
