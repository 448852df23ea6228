//! Scripted sessions (`firstshot view --script FILE`, or `FIRSTSHOT_VIEW_SCRIPT=FILE`): the
//! viewer follows the file's commands instead of the mouse and keys, then exits. This is how
//! the viewer is tested without a person (tests/viewer.rs, under Xvfb), and how a
//! demonstration can be replayed. docs/CLI.md, "Viewer", lists the commands.

use super::camera::Direction;
use firstshot::Error;
use std::path::{Path, PathBuf};

/// One command of a script.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Run until the image is the mean of this many steps (after the burn-in, and since the
    /// last camera move): the image of `firstshot SCENE --iterations N` with that camera.
    Steps(u32),
    /// Move the camera along one of its axes by this many scene units.
    Move(Direction, f64),
    /// Turn the camera: degrees to the right, degrees up.
    Turn(f64, f64),
    /// Exposure in stops relative to the automatic one (`exposure 0` resets it).
    Exposure(f64),
    /// Read back the window's image (without the overlay) and write it as a PNG.
    Screenshot(PathBuf),
    /// As the key: write the current image as EXR + PNG.
    Save,
    /// As the key: print the camera as a `[camera]` table on standard output.
    PrintCamera,
    /// Show or hide the overlay.
    Overlay(bool),
    Quit,
}

/// The commands of a script file, each with its line number. Errors name the file and the
/// line (a usage error, exit status 2, before any window opens).
pub fn load(path: &Path) -> Result<Vec<(usize, Command)>, Error> {
    let bytes = firstshot::files::read_named_input(path)?;
    let text =
        String::from_utf8(bytes).map_err(|_| Error::Usage(format!("--script {}: not UTF-8 text", path.display())))?;
    parse(&text, path)
}

/// As `load`, from the text; `source` names the file in errors.
pub fn parse(text: &str, source: &Path) -> Result<Vec<(usize, Command)>, Error> {
    let mut commands = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let err = |what: String| Error::Usage(format!("{}:{}: {what}", source.display(), i + 1));
        let words: Vec<&str> = line.split_whitespace().collect();
        let number = |k: usize, what: &str| -> Result<f64, Error> {
            let word = words.get(k).ok_or_else(|| err(format!("\"{line}\": expected {what}")))?;
            word.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| err(format!("\"{word}\": expected {what} (a finite number)")))
        };
        let arity = |n: usize, usage: &str| -> Result<(), Error> {
            if words.len() == n { Ok(()) } else { Err(err(format!("\"{line}\": expected \"{usage}\""))) }
        };
        let command = match words[0] {
            "steps" => {
                arity(2, "steps N")?;
                let n = words[1]
                    .parse::<u32>()
                    .ok()
                    .filter(|&n| n >= 1)
                    .ok_or_else(|| err(format!("\"{}\": expected a number of steps of at least 1", words[1])))?;
                Command::Steps(n)
            }
            "move" => {
                arity(3, "move forward|back|left|right|up|down DISTANCE")?;
                let direction = Direction::parse(words[1])
                    .ok_or_else(|| err(format!("\"{}\": expected forward, back, left, right, up or down", words[1])))?;
                Command::Move(direction, number(2, "a distance in scene units")?)
            }
            "turn" => {
                arity(3, "turn RIGHT_DEGREES UP_DEGREES")?;
                Command::Turn(number(1, "degrees to the right")?, number(2, "degrees up")?)
            }
            "exposure" => {
                arity(2, "exposure STOPS")?;
                Command::Exposure(number(1, "stops relative to the automatic exposure")?)
            }
            "screenshot" => {
                arity(2, "screenshot PATH.png")?;
                Command::Screenshot(PathBuf::from(words[1]))
            }
            "save" => {
                arity(1, "save")?;
                Command::Save
            }
            "print-camera" => {
                arity(1, "print-camera")?;
                Command::PrintCamera
            }
            "overlay" => {
                arity(2, "overlay on|off")?;
                match words[1] {
                    "on" => Command::Overlay(true),
                    "off" => Command::Overlay(false),
                    w => return Err(err(format!("\"{w}\": expected on or off"))),
                }
            }
            "quit" => {
                arity(1, "quit")?;
                Command::Quit
            }
            w => {
                return Err(err(format!(
                    "unknown command \"{w}\": expected steps, move, turn, exposure, screenshot, save, print-camera, overlay or quit"
                )));
            }
        };
        commands.push((i + 1, command));
    }
    Ok(commands)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_script_parses_with_comments_and_blank_lines() {
        let text = "# a session\nmove forward 50\n\nturn 10 -2.5  # right and a little down\nsteps 4\nscreenshot out/a.png\nprint-camera\nquit\n";
        let commands = parse(text, Path::new("s.txt")).unwrap();
        assert_eq!(
            commands,
            vec![
                (2, Command::Move(Direction::Forward, 50.0)),
                (4, Command::Turn(10.0, -2.5)),
                (5, Command::Steps(4)),
                (6, Command::Screenshot(PathBuf::from("out/a.png"))),
                (7, Command::PrintCamera),
                (8, Command::Quit),
            ]
        );
    }

    #[test]
    fn errors_name_the_file_the_line_and_what_was_expected() {
        for (text, expected) in [
            ("steps 0", "s.txt:1: \"0\": expected a number of steps of at least 1"),
            ("\nmove sideways 3", "s.txt:2: \"sideways\": expected forward, back"),
            ("turn 1", "s.txt:1: \"turn 1\": expected \"turn RIGHT_DEGREES UP_DEGREES\""),
            ("turn 1 nan", "s.txt:1: \"nan\": expected degrees up (a finite number)"),
            ("jump", "s.txt:1: unknown command \"jump\""),
        ] {
            let e = parse(text, Path::new("s.txt")).unwrap_err().to_string();
            assert!(e.contains(expected), "{text:?}: {e}");
        }
    }
}
