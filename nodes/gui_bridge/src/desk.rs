//! The web panel's waypoint program ("the desk"): the one program every browser sees
//! and edits, its files on the node's host, and its playback. Editing and the player are
//! [`crate::program`]'s (pure); this module applies browser requests to them, turns the
//! player's actions into the operator state's events (so a played target goes out as a
//! slider move does: rate, e-stop and reachability rules included), each target with
//! its point's move kind (`xyz_line_target` for a line).

use crate::message::ProgramView;
use crate::program::{
    list_programs, load, save, MoveMode, Player, PlayerAction, Program, ProgramFileError,
    ProgramPoint,
};
use crate::teleop::{Event, Teleop};
use crate::web::ProgramOp;
use eezybot_msgs::Time;
use ros_plumbing::feedback::Refusal;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::{Duration, Instant};

/// How long a program file's load or save may take before the panel gives up on it
/// (a hung network mount); the event loop never waits for it.
pub const FILE_TIMEOUT: Duration = Duration::from_secs(5);

/// A file operation of the desk: the run loop runs it off its event loop
/// ([`FileJob::run`] blocks, so in `spawn_blocking`, with [`FILE_TIMEOUT`]) and hands the
/// result to [`Desk::file_done`].
#[derive(Debug, Clone, PartialEq)]
pub enum FileJob {
    /// Read a program.
    Load {
        /// the program's name
        name: String,
    },
    /// Write the program.
    Save {
        /// the program's name
        name: String,
        /// what to write
        program: Program,
        /// replace an existing program of that name
        overwrite: bool,
    },
}

/// What a [`FileJob`] came to, with the program files listed afterwards (None: not
/// listed, the job timed out).
#[derive(Debug, Clone, PartialEq)]
pub enum FileDone {
    /// A load.
    Loaded {
        /// the program's name
        name: String,
        /// the program, or why not
        result: Result<Program, ProgramFileError>,
        /// the programs in the directory now
        files: Option<Vec<String>>,
    },
    /// A save.
    Saved {
        /// the program's name
        name: String,
        /// its points
        points: usize,
        /// done, or why not
        result: Result<(), ProgramFileError>,
        /// the programs in the directory now
        files: Option<Vec<String>>,
    },
}

impl FileJob {
    /// Do it (blocking) in `dir`.
    pub fn run(self, dir: &Path) -> FileDone {
        match self {
            FileJob::Load { name } => {
                let result = load(dir, &name);
                FileDone::Loaded {
                    name,
                    result,
                    files: Some(list_programs(dir)),
                }
            }
            FileJob::Save {
                name,
                program,
                overwrite,
            } => {
                let result = save(dir, &name, &program, overwrite);
                FileDone::Saved {
                    name,
                    points: program.points.len(),
                    result,
                    files: Some(list_programs(dir)),
                }
            }
        }
    }

    /// What it came to when the file system did not answer within `timeout`.
    pub fn timed_out(self, timeout: Duration) -> FileDone {
        let err = |name: &str| ProgramFileError::TimedOut {
            name: name.trim_end_matches(".csv").to_string(),
            seconds: timeout.as_secs(),
        };
        match self {
            FileJob::Load { name } => FileDone::Loaded {
                result: Err(err(&name)),
                name,
                files: None,
            },
            FileJob::Save { name, program, .. } => FileDone::Saved {
                result: Err(err(&name)),
                name,
                points: program.points.len(),
                files: None,
            },
        }
    }
}

/// What the run loop must do after the desk handled something.
#[derive(Debug, Default, PartialEq)]
pub struct DeskOutcome {
    /// The desk changed: send [`Desk::view`] to every browser.
    pub changed: bool,
    /// Run this file operation off the event loop, then call [`Desk::file_done`].
    pub file: Option<FileJob>,
}

/// The panel's program, its files and its player.
pub struct Desk {
    dir: PathBuf,
    name: String,
    program: Program,
    player: Option<Player>,
    message: String,
    /// the stamp of the last target the player published (compute_ik names it when it
    /// refuses it)
    target_stamp: Option<Time>,
    /// the player sent a target that has not been published yet
    awaiting_stamp: bool,
    /// the program files in `dir`, read again on each browser request (not on each
    /// player step: the directory is no business of the playback)
    files: Vec<String>,
    /// a file operation is under way
    file_busy: bool,
    /// the program a save found existing: the panel asks whether to replace it
    confirm_overwrite: Option<String>,
}

impl Desk {
    /// An empty program; files live in `dir`.
    pub fn new(dir: PathBuf) -> Desk {
        Desk {
            files: list_programs(&dir),
            dir,
            name: String::new(),
            program: Program::default(),
            player: None,
            message: String::new(),
            target_stamp: None,
            awaiting_stamp: false,
            file_busy: false,
            confirm_overwrite: None,
        }
    }

    /// The directory of the program files.
    pub fn dir(&self) -> &std::path::Path {
        &self.dir
    }

    /// Whether a program is playing.
    pub fn playing(&self) -> bool {
        self.player.as_ref().is_some_and(Player::is_running)
    }

    /// The desk as the browsers show it (`{"t": "program", …}`).
    pub fn view(&self) -> ProgramView {
        ProgramView {
            program: self.program.clone(),
            player: self.player.as_ref().map(Player::state),
            files: self.files.clone(),
            name: self.name.clone(),
            message: self.message.clone(),
            dir: self.dir.display().to_string(),
            confirm_overwrite: self.confirm_overwrite.clone(),
        }
    }

    /// Apply a browser's request (after `play`, run [`Desk::play_step`]). `tool`: where
    /// the arm's tool is (for `teach`), else the current target is taught; `gripper`: the
    /// claw's opening as last seen.
    pub fn request(
        &mut self,
        op: ProgramOp,
        teleop: &Teleop,
        tool: Option<[f64; 3]>,
        gripper: Option<f64>,
        now: Instant,
    ) -> DeskOutcome {
        let mut out = DeskOutcome {
            changed: true,
            ..DeskOutcome::default()
        };
        let editing = !matches!(op, ProgramOp::Play { .. } | ProgramOp::Stop);
        self.confirm_overwrite = None;
        if editing && self.playing() && !matches!(op, ProgramOp::Save { .. }) {
            self.message = "stop the program before changing it".into();
            return out;
        }
        if matches!(op, ProgramOp::Save { .. } | ProgramOp::Load { .. }) && self.file_busy {
            self.message = "another save or load is under way; try again".into();
            return out;
        }
        let result: Result<String, String> = match op {
            ProgramOp::Teach => {
                let xyz = tool.unwrap_or_else(|| teleop.target());
                let mut p = ProgramPoint::at(xyz);
                p.gripper = gripper.map(|g| g.clamp(0.0, 1.0));
                // a name that stays with the point when the list is reordered
                let taken = |k: usize| {
                    self.program
                        .points
                        .iter()
                        .any(|q| q.name == format!("P{k}"))
                };
                let k = (self.program.points.len() + 1..)
                    .find(|k| !taken(*k))
                    .unwrap_or(1);
                p.name = format!("P{k}");
                self.program.teach(p).map(|()| {
                    format!(
                        "taught P{k} at ({:.3}, {:.3}, {:.3}) m",
                        xyz[0], xyz[1], xyz[2]
                    )
                })
            }
            ProgramOp::Rename { i, name } => self.program.rename(i, &name).map(|()| String::new()),
            ProgramOp::Move { from, to } => self.program.move_to(from, to).map(|()| String::new()),
            ProgramOp::Remove { i } => self.program.remove(i).map(|()| String::new()),
            ProgramOp::Dwell { i, s } => self.program.set_dwell(i, s).map(|()| String::new()),
            ProgramOp::Mode { i, mode } => {
                match mode.as_deref().map(MoveMode::from_str).transpose() {
                    Ok(m) => self.program.set_mode(i, m).map(|()| String::new()),
                    Err(_) => Err("the move mode is joint or line".into()),
                }
            }
            ProgramOp::Play { looping } => match Player::start(&self.program, looping, now) {
                Ok(p) => {
                    // the caller runs the first step ([`Desk::play_step`])
                    self.player = Some(p);
                    self.target_stamp = None;
                    Ok(if looping {
                        "playing in a loop"
                    } else {
                        "playing"
                    }
                    .into())
                }
                Err(e) => Err(e),
            },
            ProgramOp::Stop => {
                self.stop();
                Ok("stopped".into())
            }
            ProgramOp::Save { name, overwrite } => {
                self.file_busy = true;
                out.file = Some(FileJob::Save {
                    name: name.clone(),
                    program: self.program.clone(),
                    overwrite,
                });
                Ok(format!("saving {}…", name.trim_end_matches(".csv")))
            }
            ProgramOp::Load { name } => {
                self.file_busy = true;
                out.file = Some(FileJob::Load { name: name.clone() });
                Ok(format!("loading {}…", name.trim_end_matches(".csv")))
            }
        };
        self.message = match result {
            Ok(m) => m,
            Err(e) => e,
        };
        out
    }

    /// A [`FileJob`] of [`DeskOutcome::file`] is done (or timed out).
    pub fn file_done(&mut self, done: FileDone) -> DeskOutcome {
        self.file_busy = false;
        let (files, message) = match done {
            FileDone::Loaded {
                name,
                result,
                files,
            } => (
                files,
                match result {
                    // a program that started playing meanwhile keeps playing
                    Ok(_) if self.playing() => "stop the program before loading another".into(),
                    Ok(p) => {
                        self.program = p;
                        self.name = name.trim_end_matches(".csv").to_string();
                        format!(
                            "loaded {} ({} points)",
                            self.name,
                            self.program.points.len()
                        )
                    }
                    Err(e) => e.to_string(),
                },
            ),
            FileDone::Saved {
                name,
                points,
                result,
                files,
            } => (
                files,
                match result {
                    Ok(()) => {
                        self.name = name.trim_end_matches(".csv").to_string();
                        format!("saved {points} points as {}", self.name)
                    }
                    Err(e) => {
                        if let ProgramFileError::Exists { name } = &e {
                            self.confirm_overwrite = Some(name.clone());
                        }
                        e.to_string()
                    }
                },
            ),
        };
        if let Some(files) = files {
            self.files = files;
        }
        self.message = message;
        DeskOutcome {
            changed: true,
            ..DeskOutcome::default()
        }
    }

    /// Stop playing (the e-stop, a stop request).
    pub fn stop(&mut self) {
        if let Some(p) = self.player.as_mut() {
            if p.is_running() {
                p.stop();
            }
        }
        self.awaiting_stamp = false;
    }

    /// When [`Desk::play_step`] is due again even without news (a dwell ends, a timeout).
    pub fn next_wakeup(&self) -> Option<Instant> {
        self.player
            .as_ref()
            .filter(|p| p.is_running())
            .and_then(Player::next_wakeup)
    }

    /// Run the player: `tool` is where the arm's tool is now. The targets and claw
    /// settings it plays go to `teleop` as a slider's would.
    pub fn play_step(
        &mut self,
        teleop: &mut Teleop,
        now: Instant,
        tool: Option<[f64; 3]>,
    ) -> DeskOutcome {
        let Some(player) = self.player.as_mut() else {
            return DeskOutcome::default();
        };
        // a player that just failed (a refusal) still has its `Failed` to hand out: the
        // message
        let mut out = DeskOutcome::default();
        for action in player.step(now, tool) {
            out.changed = true;
            match action {
                PlayerAction::Target { index, xyz, line } => {
                    match teleop.handle_event(Event::SetTarget { xyz, line }) {
                        Ok(_) => self.awaiting_stamp = true,
                        Err(refusal) => {
                            player.refused(&format!("point {}: {refusal}", index + 1));
                        }
                    }
                }
                PlayerAction::Gripper(opening) => {
                    // the claw is best effort: an arm without one ignores it
                    let _ = teleop.handle_event(Event::Gripper { opening });
                }
                PlayerAction::Arrived { index } => {
                    if let Some(p) = self.program.points.get(index) {
                        self.message = format!("at {}", p.label(index));
                    }
                }
                PlayerAction::Finished => self.message = "finished".into(),
                PlayerAction::Failed { index, reason } => {
                    self.message = format!("stopped at point {}: {reason}", index + 1);
                }
            }
        }
        out
    }

    /// A target was published with `stamp`: if the player sent it, remember the stamp.
    pub fn published_target(&mut self, stamp: Time) {
        if self.awaiting_stamp {
            self.awaiting_stamp = false;
            self.target_stamp = Some(stamp);
        }
    }

    /// compute_ik refused a target (its diagnostics say so): if it is the player's
    /// last, the player stops with the reason.
    pub fn refused(&mut self, refusal: &Refusal) {
        let ours = self.target_stamp.is_some_and(|t| refusal.is_for(t));
        if let (true, Some(p)) = (ours, self.player.as_mut()) {
            self.target_stamp = None;
            p.refused(&refusal.reason);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn teleop() -> Teleop {
        Teleop::new(crate::load_arm("").unwrap(), 50.0)
    }

    #[test]
    fn saves_and_loads_are_jobs_for_off_the_loop_one_at_a_time_and_a_save_asks_first() {
        let dir = std::env::temp_dir().join(format!("gui_bridge_desk_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let (t, now) = (teleop(), Instant::now());
        let mut desk = Desk::new(dir.clone());
        desk.request(ProgramOp::Teach, &t, None, None, now);
        let save = |overwrite| ProgramOp::Save {
            name: "p".into(),
            overwrite,
        };
        // the request only hands out a job: no file is touched on the loop
        let out = desk.request(save(false), &t, None, None, now);
        let job = out.file.unwrap();
        assert!(!dir.join("p.csv").exists());
        assert_eq!(desk.view().message, "saving p…");
        // one at a time
        let busy = desk.request(ProgramOp::Load { name: "p".into() }, &t, None, None, now);
        assert!(busy.file.is_none());
        assert!(desk.view().message.contains("under way"));
        desk.file_done(job.run(&dir));
        assert_eq!(desk.view().message, "saved 1 points as p");
        assert_eq!(desk.view().files, ["p"]);
        // saving again asks, replacing needs overwrite
        let job = desk.request(save(false), &t, None, None, now).file.unwrap();
        desk.file_done(job.run(&dir));
        assert_eq!(desk.view().confirm_overwrite.as_deref(), Some("p"));
        let job = desk.request(save(true), &t, None, None, now).file.unwrap();
        desk.file_done(job.run(&dir));
        assert_eq!(desk.view().message, "saved 1 points as p");
        assert!(desk.view().confirm_overwrite.is_none());
        // a job the file system never answered
        let job = desk
            .request(ProgramOp::Load { name: "p".into() }, &t, None, None, now)
            .file
            .unwrap();
        desk.file_done(job.timed_out(FILE_TIMEOUT));
        assert_eq!(
            desk.view().message,
            "program p: the file system did not answer within 5 s"
        );
        assert_eq!(desk.view().files, ["p"], "the list is kept");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
