//! The YAML line editor: a configuration text with its `servos:` block (and `leader:`
//! section) rewritten line by line, every other byte kept. Pure: no files.

use crate::WriteError;
use eezybot_kinematics::{ArmConfig, LeaderCalibration, LeaderChannel, ServoCalibrations, ServoId};

/// A number as YAML that reads back as the same `f64`: Rust's shortest round-trip form,
/// with ".0" when it would read as an integer.
fn yaml_f64(x: f64) -> String {
    let s = format!("{x}");
    if s.contains(['.', 'e', 'E', 'N', 'n']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// `{ k: v,  k: v, … }` rows whose columns line up (each `k: v,` padded to the widest in
/// its column, as in the shipped file).
fn flow_rows(rows: &[Vec<(&str, String)>]) -> Vec<String> {
    let columns = rows.iter().map(Vec::len).max().unwrap_or(0);
    let cell = |row: &Vec<(&str, String)>, i: usize| {
        let (k, v) = &row[i];
        if i + 1 < row.len() {
            format!("{k}: {v},")
        } else {
            format!("{k}: {v}")
        }
    };
    let widths: Vec<usize> = (0..columns)
        .map(|i| {
            rows.iter()
                .filter(|r| i < r.len())
                .map(|r| cell(r, i).chars().count())
                .max()
                .unwrap_or(0)
        })
        .collect();
    rows.iter()
        .map(|row| {
            let cells: Vec<String> = (0..row.len())
                .map(|i| {
                    let c = cell(row, i);
                    if i + 1 < row.len() {
                        let pad = widths[i] - c.chars().count();
                        format!("{c}{}", " ".repeat(pad))
                    } else {
                        c
                    }
                })
                .collect();
            format!("{{ {} }}", cells.join(" "))
        })
        .collect()
}

fn servo_flows(servos: &ServoCalibrations) -> Vec<String> {
    let rows: Vec<Vec<(&str, String)>> = ServoId::ALL
        .iter()
        .map(|&s| {
            let c = servos.get(s);
            vec![
                ("offset_deg", yaml_f64(c.offset_deg)),
                ("gain", yaml_f64(c.gain)),
                ("min_deg", yaml_f64(c.min_deg)),
                ("max_deg", yaml_f64(c.max_deg)),
                ("pulse_min_us", c.pulse_min_us.to_string()),
                ("pulse_max_us", c.pulse_max_us.to_string()),
            ]
        })
        .collect();
    flow_rows(&rows)
}

const SERVO_KEYS: [&str; 4] = ["base", "shoulder", "elbow", "gripper"];

/// `key:` padded to the width of `shoulder:`, as the shipped file aligns them.
fn key_cell(key: &str) -> String {
    let k = format!("{key}:");
    format!("{k:<9}")
}

/// The `leader:` section's lines (each ending in `\n`), keys aligned as in `servos:`.
fn leader_lines(leader: &LeaderCalibration, newline: &str) -> Vec<String> {
    let mut lines = vec![
        format!("leader:{newline}"),
        format!("  adc_max: {}{newline}", leader.adc_max),
    ];
    let present: Vec<(usize, &LeaderChannel)> = ServoId::ALL
        .iter()
        .enumerate()
        .filter_map(|(i, &s)| leader.get(s).map(|c| (i, c)))
        .collect();
    let rows: Vec<Vec<(&str, String)>> = present
        .iter()
        .map(|(_, c)| {
            vec![
                ("counts_a", yaml_f64(c.counts_a)),
                ("input_a", yaml_f64(c.input_a)),
                ("counts_b", yaml_f64(c.counts_b)),
                ("input_b", yaml_f64(c.input_b)),
            ]
        })
        .collect();
    for ((i, _), flow) in present.iter().zip(flow_rows(&rows)) {
        lines.push(format!("  {} {flow}{newline}", key_cell(SERVO_KEYS[*i])));
    }
    lines
}

/// The comment written above a `leader:` section the writer adds.
const LEADER_COMMENT: &str = "# Leader arm potentiometers (calibration wizard): per channel, the ADC readings at two\n# reference poses and the inputs there (deg; the claw: opening 0..1), in the servos' terms\n# (base_joint, shoulder_joint, forearm elevation, opening). input is linear in the reading.\n";

fn indent_of(line: &str) -> usize {
    line.len() - line.trim_start_matches([' ', '\t']).len()
}

fn is_blank_or_comment(line: &str) -> bool {
    let t = line.trim();
    t.is_empty() || t.starts_with('#')
}

/// The key of a `key:` line (`None` for other lines), and the text after the colon.
fn key_of(line: &str) -> Option<(&str, &str)> {
    let t = line.trim_start_matches([' ', '\t']);
    if t.starts_with('#') {
        return None;
    }
    let colon = t.find(':')?;
    let key = &t[..colon];
    let rest = &t[colon + 1..];
    let ok = !key.is_empty()
        && key
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        && (rest.is_empty() || rest.starts_with([' ', '\t', '\r', '\n']));
    ok.then_some((key, rest))
}

/// The lines `start+1 ..` belonging to a `key:` line at `start` with indent `indent`:
/// until the next non-blank line indented no deeper (for a top-level key, a column-0
/// comment ends it too), trailing blank and comment lines excluded.
fn block_end(lines: &[&str], start: usize, indent: usize) -> usize {
    let mut end = start + 1;
    let mut i = start + 1;
    while i < lines.len() {
        let l = lines[i];
        if l.trim().is_empty() {
            i += 1;
            continue;
        }
        let ind = indent_of(l);
        if ind <= indent && !(l.trim_start().starts_with('#') && ind > 0) {
            break;
        }
        if !is_blank_or_comment(l) {
            end = i + 1;
        }
        i += 1;
    }
    end
}

/// The value of a `key: { … }` line replaced by `flow`, keeping the prefix (key and its
/// alignment) and whatever follows the closing brace (a comment); `None` when the line
/// has no one-line flow mapping.
fn replace_flow(line: &str, flow: &str) -> Option<String> {
    let (_, rest) = key_of(line)?;
    if !rest.trim_start().starts_with('{') {
        return None;
    }
    let open = line.find('{')?;
    let close = open + line[open..].find('}')?;
    if line[open + 1..close].contains('{') {
        return None;
    }
    Some(format!("{}{flow}{}", &line[..open], &line[close + 1..]))
}

/// The new text of an arm configuration: `original` with its `servos:` block rewritten
/// to `servos` (and, given `leader`, its `leader:` section replaced or appended). Every
/// other line is kept byte for byte; inside `servos:`, a servo written as a one-line flow
/// mapping `name: { … }` keeps its key, alignment and trailing comment and gets its
/// values replaced, columns aligned as in the shipped file; a servo written otherwise (a
/// nested block) is replaced by such a line; a missing one is added. Pure: the result is
/// verified to load (`ArmConfig::from_yaml`) back to exactly `servos` (and `leader`),
/// with geometry, limits, motion (and an unchanged leader) equal to the original's.
pub fn calibration_text(
    original: &str,
    servos: &ServoCalibrations,
    leader: Option<&LeaderCalibration>,
) -> Result<String, WriteError> {
    let before = ArmConfig::from_yaml(original, "the existing configuration")
        .map_err(WriteError::Original)?;
    servos
        .validate("the new calibration")
        .map_err(WriteError::Invalid)?;
    if let Some(l) = leader {
        l.validate("the new calibration")
            .map_err(WriteError::Invalid)?;
    }
    let newline = if original.contains("\r\n") {
        "\r\n"
    } else {
        "\n"
    };
    // a last line without its newline gets one while rewriting (removed again below)
    let padded;
    let added_newline = !original.is_empty() && !original.ends_with('\n');
    let source = if added_newline {
        padded = format!("{original}{newline}");
        padded.as_str()
    } else {
        original
    };
    let lines: Vec<&str> = source.split_inclusive('\n').collect();
    let flows = servo_flows(servos);
    let mut out: Vec<String> = Vec::with_capacity(lines.len() + 8);
    let top = |l: &str, name: &str| indent_of(l) == 0 && key_of(l).is_some_and(|(k, _)| k == name);
    let mut i = 0;
    let mut servos_done = false;
    let mut leader_done = leader.is_none();
    while i < lines.len() {
        let line = lines[i];
        if !servos_done && top(line, "servos") {
            let end = block_end(&lines, i, 0);
            let inline = key_of(line).is_some_and(|(_, rest)| !is_blank_or_comment(rest));
            if inline {
                // `servos: { … }` on one line (or more): replace it by a block
                out.push(format!("servos:{newline}"));
                for (k, flow) in SERVO_KEYS.iter().zip(&flows) {
                    out.push(format!("  {} {flow}{newline}", key_cell(k)));
                }
            } else {
                rewrite_servo_block(&lines[i..end], &flows, newline, &mut out);
            }
            servos_done = true;
            i = end;
            continue;
        }
        if !leader_done && top(line, "leader") {
            let end = block_end(&lines, i, 0);
            if let Some(l) = leader {
                out.extend(leader_lines(l, newline));
            }
            leader_done = true;
            i = end;
            continue;
        }
        out.push(line.to_string());
        i += 1;
    }
    let appended = !servos_done || (leader.is_some() && !leader_done);
    if !servos_done {
        out.push(format!("{newline}servos:{newline}"));
        for (k, flow) in SERVO_KEYS.iter().zip(&flows) {
            out.push(format!("  {} {flow}{newline}", key_cell(k)));
        }
    }
    if let (false, Some(l)) = (leader_done, leader) {
        out.push(format!(
            "{newline}{}",
            LEADER_COMMENT.replace('\n', newline)
        ));
        out.extend(leader_lines(l, newline));
    }
    let mut text: String = out.concat();
    if added_newline && !appended && text.ends_with(newline) {
        // a file without a final newline stays that way when only values changed
        text.truncate(text.len() - newline.len());
    }
    let after = ArmConfig::from_yaml(&text, "the rewritten configuration")
        .map_err(|e| WriteError::Verify(e.to_string()))?;
    let want_leader = leader.copied().or(before.leader);
    let mut mismatch = Vec::new();
    if after.servos != *servos {
        mismatch.push(format!("servos {:?} instead of {servos:?}", after.servos));
    }
    if after.leader != want_leader {
        mismatch.push(format!(
            "leader {:?} instead of {want_leader:?}",
            after.leader
        ));
    }
    if (after.geometry, after.limits_deg, after.motion)
        != (before.geometry, before.limits_deg, before.motion)
    {
        mismatch.push("geometry, limits or motion changed".to_string());
    }
    if mismatch.is_empty() {
        Ok(text)
    } else {
        Err(WriteError::Verify(mismatch.join("; ")))
    }
}

/// Rewrite the lines of a `servos:` block (its key line first).
fn rewrite_servo_block(block: &[&str], flows: &[String], newline: &str, out: &mut Vec<String>) {
    out.push(block[0].to_string());
    let entry_indent = block[1..]
        .iter()
        .find(|l| !is_blank_or_comment(l))
        .map_or(2, |l| indent_of(l));
    let mut seen = [false; 4];
    let mut last_entry_out = out.len();
    let mut j = 1;
    while j < block.len() {
        let line = block[j];
        let servo = if !is_blank_or_comment(line) && indent_of(line) == entry_indent {
            key_of(line).and_then(|(k, _)| SERVO_KEYS.iter().position(|s| *s == k))
        } else {
            None
        };
        let Some(s) = servo else {
            out.push(line.to_string());
            j += 1;
            continue;
        };
        let end = block_end(block, j, entry_indent);
        let one_line = end == j + 1;
        match replace_flow(line, &flows[s]).filter(|_| one_line) {
            Some(new) => out.push(new),
            None => out.push(format!(
                "{}{}: {}{newline}",
                &line[..entry_indent],
                SERVO_KEYS[s],
                flows[s]
            )),
        }
        seen[s] = true;
        last_entry_out = out.len();
        j = end;
    }
    let missing: Vec<String> = (0..4)
        .filter(|&s| !seen[s])
        .map(|s| {
            format!(
                "{}{} {}{newline}",
                " ".repeat(entry_indent),
                key_cell(SERVO_KEYS[s]),
                flows[s]
            )
        })
        .collect();
    for (n, line) in missing.into_iter().enumerate() {
        out.insert(last_entry_out + n, line);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::odd_calibration;
    use eezybot_kinematics::SHIPPED_ARM_YAML;

    #[test]
    fn writing_the_shipped_values_back_changes_nothing() {
        let text = calibration_text(SHIPPED_ARM_YAML, &ServoCalibrations::default(), None).unwrap();
        assert_eq!(text, SHIPPED_ARM_YAML);
    }

    #[test]
    fn new_values_round_trip_and_nothing_else_changes() {
        let new = odd_calibration();
        let text = calibration_text(SHIPPED_ARM_YAML, &new, None).unwrap();
        let back = ArmConfig::from_yaml(&text, "t").unwrap();
        assert_eq!(back.servos, new);
        assert_eq!(
            back.servos.elbow.offset_deg.to_bits(),
            (0.1f64 + 0.2).to_bits()
        );
        // every line outside the four servo lines is byte for byte the same
        let (old, newl): (Vec<&str>, Vec<&str>) =
            (SHIPPED_ARM_YAML.lines().collect(), text.lines().collect());
        assert_eq!(old.len(), newl.len());
        let changed: Vec<usize> = (0..old.len()).filter(|&i| old[i] != newl[i]).collect();
        assert_eq!(changed.len(), 4, "{changed:?}");
        for i in changed {
            let key = ["base:", "shoulder:", "elbow:", "gripper:"];
            assert!(
                key.iter().any(|k| old[i].trim_start().starts_with(k)),
                "{}",
                old[i]
            );
            // key and alignment kept
            let prefix = &old[i][..old[i].find('{').unwrap()];
            assert!(newl[i].starts_with(prefix), "{}", newl[i]);
        }
        // and a second save from the new text is stable
        assert_eq!(calibration_text(&text, &new, None).unwrap(), text);
    }

    #[test]
    fn other_layouts_are_rewritten_too() {
        // a nested block, a missing servo, a comment after an entry, CRLF line ends
        let original = "# mine\r\nservos:\r\n  # the base\r\n  base:\r\n    offset_deg: 91.0\r\n    gain: -2.0\r\n    min_deg: 0.0\r\n    max_deg: 180.0\r\n    pulse_min_us: 544\r\n    pulse_max_us: 2400\r\n  shoulder: { offset_deg: 180.0, gain: -1.0, min_deg: 0.0, max_deg: 180.0, pulse_min_us: 544, pulse_max_us: 2400 }  # measured\r\n\r\n# geometry next\r\ngeometry:\r\n  shoulder_height_m: 0.085\r\n";
        let new = odd_calibration();
        let text = calibration_text(original, &new, None).unwrap();
        let back = ArmConfig::from_yaml(&text, "t").unwrap();
        assert_eq!(back.servos, new);
        assert_eq!(back.geometry.shoulder_height_m, 0.085);
        assert!(
            text.contains("  # the base\r\n")
                && text.contains("}  # measured\r\n")
                && text.contains("# geometry next\r\n"),
            "{text}"
        );
        assert!(!text.replace("\r\n", "").contains('\n'), "{text:?}");
        // no servos section at all; a flow-style one
        for original in ["geometry: { shoulder_height_m: 0.09 }\n", "servos: { base: { offset_deg: 90.0, gain: -2.0, min_deg: 0.0, max_deg: 180.0, pulse_min_us: 544, pulse_max_us: 2400 } }\nmotion: {}\n"] {
            let text = calibration_text(original, &new, None).unwrap();
            assert_eq!(ArmConfig::from_yaml(&text, "t").unwrap().servos, new, "{text}");
        }
    }

    #[test]
    fn leader_section_is_added_replaced_and_loaded() {
        let mut leader = LeaderCalibration::default();
        leader.set(
            ServoId::Base,
            LeaderChannel {
                counts_a: 512.0,
                input_a: 0.0,
                counts_b: 690.5,
                input_b: 45.0,
            },
        );
        leader.set(
            ServoId::Gripper,
            LeaderChannel {
                counts_a: 300.0,
                input_a: 0.0,
                counts_b: 700.0,
                input_b: 1.0,
            },
        );
        let servos = ServoCalibrations::default();
        let text = calibration_text(SHIPPED_ARM_YAML, &servos, Some(&leader)).unwrap();
        assert!(
            text.starts_with(SHIPPED_ARM_YAML),
            "appended after the untouched file"
        );
        let back = ArmConfig::from_yaml(&text, "t").unwrap();
        assert_eq!(back.leader, Some(leader));
        // replaced in place the second time; the file without a leader keeps loading
        let mut other = leader;
        other.adc_max = 4095;
        other.base = None;
        let again = calibration_text(&text, &servos, Some(&other)).unwrap();
        assert_eq!(
            ArmConfig::from_yaml(&again, "t").unwrap().leader,
            Some(other)
        );
        assert_eq!(again.matches("leader:").count(), 1);
        assert!(again.starts_with(SHIPPED_ARM_YAML));
        // servos only: the leader section stays
        let kept = calibration_text(&again, &odd_calibration(), None).unwrap();
        assert_eq!(
            ArmConfig::from_yaml(&kept, "t").unwrap().leader,
            Some(other)
        );
    }

    #[test]
    fn invalid_inputs_are_refused_before_writing() {
        let mut bad = ServoCalibrations::default();
        bad.elbow.min_deg = 200.0;
        assert!(matches!(
            calibration_text(SHIPPED_ARM_YAML, &bad, None),
            Err(WriteError::Invalid(_))
        ));
        bad = ServoCalibrations::default();
        bad.base.gain = f64::NAN;
        assert!(matches!(
            calibration_text(SHIPPED_ARM_YAML, &bad, None),
            Err(WriteError::Invalid(_))
        ));
        let err = calibration_text("geometry: [", &ServoCalibrations::default(), None).unwrap_err();
        assert!(matches!(err, WriteError::Original(_)), "{err}");
    }

    #[test]
    fn the_issue_s_arm_is_written_and_loads_back() {
        // what eezybot_kinematics::calibration derives for the arm of issue 22 (every
        // horn 7° off, the forearm servo mounted reversed, the claw opened as far as its
        // servo goes)
        let mut new = ServoCalibrations::default();
        (new.base.offset_deg, new.base.gain) = (97.0, -2.0);
        (new.shoulder.offset_deg, new.shoulder.gain) = (187.0, -1.0);
        (new.elbow.offset_deg, new.elbow.gain) = (97.0, -1.0);
        (new.gripper.offset_deg, new.gripper.gain) = (67.0, 113.0);
        (new.gripper.min_deg, new.gripper.max_deg) = (67.0, 180.0);
        let text = calibration_text(SHIPPED_ARM_YAML, &new, None).unwrap();
        assert_eq!(ArmConfig::from_yaml(&text, "t").unwrap().servos, new);
    }
}
