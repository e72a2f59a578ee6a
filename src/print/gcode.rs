//! G-code import into a toolpath.
//!
//! Accepts the subset a printer needs: straight moves G0/G1 (X Y Z E F), arcs G2 (clockwise) and
//! G3 (counter-clockwise) in the XY plane (G17) with I/J (the centre's offset from the start) or
//! R (the radius; R < 0: the arc over half a turn) and an optional helical Z, G4 dwell (a bare G4
//! waits for nothing), G90/G91, M82/M83, G92, G21, and the flow and feed overrides M221/M220.
//! Slicers also write commands that set the machine's state or label the print without moving
//! the nozzle or changing the material laid down: temperatures, fans, object labels, messages,
//! progress, steppers, motion limits, firmware macros (`PRINT_START`) and homing or bed probing
//! before the first move ([`super::gcode_dialect`] lists them, and says how comments are read).
//! These are skipped, and counted in a note ([`GcodeNotes`]) said once at start-up. So are the
//! motion commands after the last extrusion (a park move, Cura's end-of-print `G28 X0`): the part
//! is laid by then, and a nozzle dragged through it would not print it. Anything else is refused
//! with its line number rather than skipped, because a silently ignored command (a homing move in
//! mid-print) would print a different part.
//!
//! E is the extruder axis (`extruder_axis` names another letter, as a paste printer's U); it
//! counts length of material through the outlet (`e_unit` metres per unit), or length of
//! filament of `filament_diameter` (converted by volume: E × π d² / 4 through the outlet's
//! area). A file whose E per unit of path lays far too little material for a bead (as filament
//! length read as extrudate would) is warned of. In pump mode (`flow_unit`, see
//! [`super::pump`]) there is no E: the flow is switched and set by M-codes or the S word.
//!
//! Moves of E alone (the nozzle standing still) deposit nothing: a retraction (E backwards,
//! also firmware retraction G10) and the un-retraction that restores it (E forwards, G11) leave
//! no net material, and an advance beyond the restored amount (a prime in place) is dropped, its
//! length counted in the note: strand deposits material only while the nozzle moves. Such moves
//! take no time. Only a net advance of E during a move deposits material.
//!
//! One command per line; a word is a letter followed directly by a number without exponent
//! (`G1X10E.5` is fine, `X 10` is not).

use super::arc::{Arc, ArcInput, Sense};
use super::gcode_dialect::{first_word, free_text_command, homing_command, is_skipped_m, strip_comments};
use super::pump::Pump;
use super::toolpath::{Move, MoveKind, Toolpath, ToolpathError};

/// Metres of material through the outlet per unit of E when neither `e_unit` nor
/// `filament_diameter` is given: E counts millimetres of extrudate.
const DEFAULT_E_UNIT: f64 = 1e-3;

/// Extrudate length over path length below which a file's E looks like filament length: a
/// bead of less than a fifth of the outlet's area. Extrudate E lays about the outlet's area
/// (paper 000's case 1: 1.12); 1.75 mm filament E from an FDM slicer lays a few hundredths.
const FILAMENT_LIKE_E_PER_PATH: f64 = 0.2;

/// How G-code numbers map to the world. In scenario TOML this is `[print.gcode_options]`.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GcodeOptions {
    /// metres per G-code length unit (1e-3: millimetres)
    pub unit: f64,
    /// metres of material through the nozzle per unit of E (None: 1e-3, E counts mm of
    /// extrudate length through the outlet); not with `filament_diameter`
    pub e_unit: Option<f64>,
    /// diameter of the filament E counts the length of, in G-code length units: E is converted
    /// by volume (E × π d² / 4 through the outlet's area); not with `e_unit`
    pub filament_diameter: Option<f64>,
    /// the letter of the extruder axis ('E'; a paste printer's Slic3r file may drive 'U')
    pub extruder_axis: char,
    /// pump mode: m³/s of material per unit of the pump's S word (1 L/min: 1.6667e-5); the
    /// file then has no E (see `print::pump`)
    pub flow_unit: Option<f64>,
    /// pump mode: the M-code that switches the pump on ("M3" when not given)
    pub pump_on: Option<String>,
    /// pump mode: the M-code that switches the pump off ("M5" when not given)
    pub pump_off: Option<String>,
    /// world position of the G-code origin [m]
    pub origin: [f64; 3],
    /// start position of the nozzle in G-code coordinates before the first move
    pub start: [f64; 3],
    /// feed rate before any F word, G-code units per minute
    pub default_feed: f64,
}

impl Default for GcodeOptions {
    /// Millimetres, E in mm of extrudate, no pump, origin at the world origin, 3000 mm/min (50
    /// mm/s, a typical concrete printing speed) until the file sets F.
    fn default() -> Self {
        GcodeOptions {
            unit: 1e-3,
            e_unit: None,
            filament_diameter: None,
            extruder_axis: 'E',
            flow_unit: None,
            pump_on: None,
            pump_off: None,
            origin: [0.0; 3],
            start: [0.0; 3],
            default_feed: 3000.0,
        }
    }
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GcodeError {
    /// A command (or use of one) the importer does not implement; `line` is 1-based.
    #[error("gcode line {line}: unsupported command {word} ({text:?}){}", reason_suffix(.reason))]
    Unsupported { line: usize, word: String, text: String, reason: String },
    /// A line that is not valid G-code; `line` is 1-based.
    #[error("gcode line {line}: {message} ({text:?})")]
    Malformed { line: usize, message: String, text: String },
    #[error("print.gcode_options.{key}: {message}")]
    Option { key: &'static str, message: String },
    #[error("gcode: {0}")]
    Toolpath(#[from] ToolpathError),
}

fn reason_suffix(reason: &str) -> String {
    if reason.is_empty() {
        String::new()
    } else {
        format!(": {reason}")
    }
}

/// Parse G-code into a toolpath starting at t = 0. Feed rates are in G-code units per minute;
/// a G1 that advances E by dE over a length s at feed F lasts s / (F/60) and extrudes at
/// U = dE · e_unit / duration. Moves with no net E advance are travels. Options that convert
/// by volume (`filament_diameter`, pump mode) need the outlet: [`parse_gcode_for_outlet`].
pub fn parse_gcode(text: &str, opts: &GcodeOptions) -> Result<Toolpath, GcodeError> {
    parse_gcode_with_notes(text, opts).map(|(p, _)| p)
}

/// [`parse_gcode`], with what it skipped.
pub fn parse_gcode_with_notes(text: &str, opts: &GcodeOptions) -> Result<(Toolpath, GcodeNotes), GcodeError> {
    import(text, opts, None)
}

/// [`parse_gcode_with_notes`] for a nozzle whose outlet has area `outlet_area` [m²], which
/// turns volumes (of filament, of a pump's flow) into the extrusion speed U through it.
pub fn parse_gcode_for_outlet(text: &str, opts: &GcodeOptions, outlet_area: f64) -> Result<(Toolpath, GcodeNotes), GcodeError> {
    import(text, opts, Some(outlet_area))
}

/// What the import skipped or dropped, for one line at start-up.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GcodeNotes {
    /// Machine-state commands skipped, by command (upper-cased), with how often.
    pub skipped: std::collections::BTreeMap<String, usize>,
    /// Moves of E alone with the nozzle still (retractions, un-retractions, primes).
    pub e_only: usize,
    /// E advanced in place beyond the retracted amount, dropped [G-code E units].
    pub primed: f64,
    /// Pump mode: volume pumped while the nozzle stood still, dropped [m³].
    pub pumped_in_place: f64,
    /// Motion commands after the last extrusion, skipped (homing, parking, travels).
    pub after_last_extrusion: usize,
    /// What looks wrong with the file though it imports (said as warnings).
    pub warnings: Vec<String>,
}

impl std::fmt::Display for GcodeNotes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let list: Vec<String> = self.skipped.iter().map(|(k, n)| format!("{k} x{n}")).collect();
        write!(f, "skipped {} machine-state command(s) (temperatures, fans, object labels, messages, progress, steppers, limits, macros, homing before the first move): {}", self.skipped.values().sum::<usize>(), if list.is_empty() { "none".into() } else { list.join(", ") })?;
        if self.e_only > 0 {
            write!(f, "; {} move(s) of E alone (retract/un-retract) deposit nothing", self.e_only)?;
        }
        if self.primed > 0.0 {
            write!(f, ", {:.6} E units primed in place dropped", self.primed)?;
        }
        if self.pumped_in_place > 0.0 {
            write!(f, "; {:.6e} m³ pumped with the nozzle still dropped", self.pumped_in_place)?;
        }
        if self.after_last_extrusion > 0 {
            write!(f, "; {} motion command(s) after the last extrusion skipped (homing, parking, travels)", self.after_last_extrusion)?;
        }
        Ok(())
    }
}

impl GcodeNotes {
    /// Whether anything was skipped or dropped (warnings aside).
    pub fn is_empty(&self) -> bool {
        self.skipped.is_empty() && self.e_only == 0 && self.pumped_in_place == 0.0 && self.after_last_extrusion == 0
    }
}

/// Read the file line by line: skipped lines are counted, the rest interpreted.
fn import(text: &str, opts: &GcodeOptions, outlet_area: Option<f64>) -> Result<(Toolpath, GcodeNotes), GcodeError> {
    opts.validate()?;
    let mut machine = Machine::new(opts, outlet_area)?;
    for (i, raw) in text.lines().enumerate() {
        machine.line = i + 1;
        let at_line = |e: LineError| match e {
            LineError::Unsupported { word, reason } => {
                GcodeError::Unsupported { line: i + 1, word, text: raw.trim().to_string(), reason }
            }
            LineError::Malformed(message) => {
                GcodeError::Malformed { line: i + 1, message, text: raw.trim().to_string() }
            }
        };
        // the pump's own M-codes (M106/M107 in a fan-style setup) are read, not skipped
        let pump_command = machine.pump.as_ref().is_some_and(|p| {
            first_word(raw).and_then(|w| w.strip_prefix('M')?.parse().ok()).is_some_and(|m| p.is_command(m))
        });
        if !pump_command {
            if let Some(name) = free_text_command(raw) {
                machine.count_skipped(&name);
                continue;
            }
            if let Some(name) = homing_command(raw) {
                machine.home(name, raw.trim());
                continue;
            }
        }
        let words = tokenize(raw, opts.extruder_axis).map_err(at_line)?;
        machine.execute(&words).map_err(at_line)?;
        machine.refuse_homing_before_an_extrusion()?;
    }
    machine.finish()
}

impl GcodeOptions {
    /// Metres of material through the outlet per unit of E: `e_unit`, or filament of
    /// `filament_diameter` by volume through the outlet (`outlet_area` is asked for only then),
    /// or [`DEFAULT_E_UNIT`].
    pub fn metres_per_e<E>(&self, outlet_area: impl FnOnce() -> Result<f64, E>) -> Result<f64, E> {
        Ok(match (self.e_unit, self.filament_diameter) {
            (Some(e), _) => e,
            // E × unit of filament of cross-section π (d unit)² / 4, through the outlet
            (None, Some(d)) => self.unit * std::f64::consts::PI * (d * self.unit).powi(2) / 4.0 / outlet_area()?,
            (None, None) => DEFAULT_E_UNIT,
        })
    }

    /// Check every option is usable.
    pub fn validate(&self) -> Result<(), GcodeError> {
        let bad = |key, message: String| Err(GcodeError::Option { key, message });
        let given = [("e_unit", self.e_unit), ("filament_diameter", self.filament_diameter), ("flow_unit", self.flow_unit)];
        for (key, v) in [("unit", Some(self.unit)), ("default_feed", Some(self.default_feed))].into_iter().chain(given) {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return bad(key, format!("{key} = {v} must be finite and > 0"));
            }
        }
        for (key, v) in [("origin", self.origin), ("start", self.start)] {
            if !v.iter().all(|x| x.is_finite()) {
                return bad(key, format!("{key} = {v:?} must be finite"));
            }
        }
        // E counts one thing: extrudate (e_unit), filament (filament_diameter), or nothing (pump)
        if let [(a, _), (b, _), ..] = given.iter().filter(|(_, v)| v.is_some()).collect::<Vec<_>>()[..] {
            return bad(*b, format!("{a} and {b} both say what E counts; give one (flow_unit: pump mode, no E)"));
        }
        let axis = self.extruder_axis.to_ascii_uppercase();
        if !EXTRUDER_AXES.contains(axis) {
            return bad("extruder_axis", format!("extruder_axis = {:?} must be one of the axis letters {EXTRUDER_AXES}", self.extruder_axis));
        }
        if self.flow_unit.is_some() && axis != 'E' {
            return bad("extruder_axis", "pump mode (flow_unit) has no extruder axis".into());
        }
        if self.flow_unit.is_none() {
            for (key, v) in [("pump_on", &self.pump_on), ("pump_off", &self.pump_off)] {
                if v.is_some() {
                    return bad(key, format!("{key} switches the pump of pump mode, which flow_unit (m³/s per unit of S) turns on; give flow_unit"));
                }
            }
        }
        Ok(())
    }
}

/// Letters `extruder_axis` may name: E and the axes G-code leaves free for extra motors.
const EXTRUDER_AXES: &str = "EABCDUVW";

/// A line's problem, before the line number and text are attached.
enum LineError {
    Unsupported { word: String, reason: String },
    Malformed(String),
}

/// One word: an upper-cased letter and its number, plus its spelling for messages.
struct Word {
    letter: char,
    value: f64,
    text: String,
}

/// Letters of the supported commands and their parameters; others are "unknown words".
const KNOWN_LETTERS: &str = "GMTNXYZEFPSIJKR";

/// Split a line into words, dropping comments and a `*` checksum (as
/// [`super::gcode_dialect`] reads them). The extruder axis's words become E words.
fn tokenize(raw: &str, extruder_axis: char) -> Result<Vec<Word>, LineError> {
    let code: Vec<char> = strip_comments(raw).map_err(LineError::Malformed)?.chars().collect();
    let extruder_axis = extruder_axis.to_ascii_uppercase();
    // '%' alone marks the start or end of a program on some controllers.
    if code.iter().collect::<String>().trim() == "%" {
        return Ok(Vec::new());
    }
    let mut words: Vec<Word> = Vec::new();
    let mut i = 0;
    while i < code.len() {
        let c = code[i];
        i += 1;
        if c.is_whitespace() {
            continue;
        }
        if !c.is_ascii_alphabetic() {
            return Err(LineError::Malformed(format!("unexpected character {c:?}")));
        }
        let letter = match c.to_ascii_uppercase() {
            'E' if extruder_axis != 'E' => {
                return Err(LineError::Malformed(format!(
                    "an E word, but the extruder is axis {extruder_axis} (print.gcode_options.extruder_axis)"
                )))
            }
            a if a == extruder_axis => 'E',
            a => a,
        };
        let start = i;
        while i < code.len() && !code[i].is_whitespace() && !code[i].is_ascii_alphabetic() {
            i += 1;
        }
        let number: String = code[start..i].iter().collect();
        if number.is_empty() {
            let found: String = code[i..].iter().take_while(|c| !c.is_whitespace()).collect();
            return Err(LineError::Malformed(match found.is_empty() {
                true => format!("{letter} has no number"),
                false => format!("{letter} must be followed by a number, found {found:?}"),
            }));
        }
        let value = parse_number(&number).ok_or_else(|| LineError::Malformed(format!("bad number {number:?} after {letter}")))?;
        if words.iter().any(|w| w.letter == letter) {
            return Err(LineError::Malformed(format!("{letter} appears twice on the line")));
        }
        words.push(Word { letter, value, text: format!("{}{number}", c.to_ascii_uppercase()) });
    }
    Ok(words)
}

/// A G-code number: optional sign, digits with at most one decimal point, no exponent (E is an
/// axis letter), finite.
fn parse_number(s: &str) -> Option<f64> {
    let body = s.strip_prefix(['+', '-']).unwrap_or(s);
    let digits = body.chars().filter(|c| c.is_ascii_digit()).count();
    let points = body.chars().filter(|&c| c == '.').count();
    if digits == 0 || points > 1 || digits + points != body.len() {
        return None;
    }
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// The interpreter state while reading a file.
struct Machine<'a> {
    opts: &'a GcodeOptions,
    /// Physical nozzle position in G-code units; G92 leaves it alone and moves `offset` instead.
    machine: [f64; 3],
    /// Logical (file) coordinate = machine - offset.
    offset: [f64; 3],
    /// Logical E position, tracked in both E modes so switching modes stays consistent.
    e: f64,
    absolute_xyz: bool,
    absolute_e: bool,
    /// Feed rate, G-code units per minute.
    feed: f64,
    t: f64,
    /// World position of the nozzle [m]; kept so each move starts exactly where the last ended.
    world: [f64; 3],
    moves: Vec<Move>,
    notes: GcodeNotes,
    /// E retracted with the nozzle still and not yet restored [E units].
    retracted: f64,
    /// M221 flow and M220 feed overrides, as factors.
    flow: f64,
    feed_factor: f64,
    /// Metres of material through the outlet per unit of E.
    e_unit: f64,
    /// Pump mode's pump.
    pump: Option<Pump>,
    /// The line being read (1-based), and the line each move came from.
    line: usize,
    move_lines: Vec<usize>,
    /// The line of the last move that deposits.
    last_print_line: Option<usize>,
    /// Homing, parking or probing commands after the first move, skipped if no extrusion
    /// follows them.
    homed: Vec<Homing>,
}

/// A homing, parking or probing line after the first move.
struct Homing {
    line: usize,
    word: String,
    text: String,
}

impl Homing {
    fn error(&self) -> GcodeError {
        GcodeError::Unsupported {
            line: self.line,
            word: self.word.clone(),
            text: self.text.clone(),
            reason: "homing, parking or probing between the first move and the last extrusion would move the nozzle to a position strand does not know (skipped only before the first move and after the last extrusion)".into(),
        }
    }
}

impl<'a> Machine<'a> {
    fn new(opts: &'a GcodeOptions, outlet_area: Option<f64>) -> Result<Self, GcodeError> {
        let outlet = |key: &'static str| {
            outlet_area.filter(|a| a.is_finite() && *a > 0.0).ok_or_else(|| GcodeError::Option {
                key,
                message: format!("{key} converts by volume, through the nozzle's outlet area: import the file through a scenario's [print]"),
            })
        };
        let e_unit = opts.metres_per_e(|| outlet("filament_diameter"))?;
        let pump = match opts.flow_unit {
            Some(q) => Some(
                Pump::new(opts.pump_on.as_deref(), opts.pump_off.as_deref(), q, outlet("flow_unit")?)
                    .map_err(|(key, message)| GcodeError::Option { key, message })?,
            ),
            None => None,
        };
        Ok(Machine {
            opts,
            machine: opts.start,
            offset: [0.0; 3],
            e: 0.0,
            absolute_xyz: true,
            absolute_e: true,
            feed: opts.default_feed,
            t: 0.0,
            world: std::array::from_fn(|i| opts.origin[i] + opts.unit * opts.start[i]),
            moves: Vec::new(),
            notes: GcodeNotes::default(),
            retracted: 0.0,
            flow: 1.0,
            feed_factor: 1.0,
            e_unit,
            pump,
            line: 0,
            move_lines: Vec::new(),
            last_print_line: None,
            homed: Vec::new(),
        })
    }

    /// Count a skipped command in the note.
    fn count_skipped(&mut self, command: &str) {
        *self.notes.skipped.entry(command.to_ascii_uppercase()).or_default() += 1;
    }

    /// A homing, parking or probing line: skipped before the first move; after it, kept aside
    /// until an extrusion follows (an error) or the file ends (skipped).
    fn home(&mut self, word: String, text: &str) {
        if self.moves.is_empty() {
            self.count_skipped(&word);
        } else {
            self.homed.push(Homing { line: self.line, word, text: text.to_string() });
        }
    }

    /// The first homing line before an extrusion, as the error it is.
    fn refuse_homing_before_an_extrusion(&self) -> Result<(), GcodeError> {
        match self.homed.first() {
            Some(h) if self.last_print_line.is_some_and(|l| l > h.line) => Err(h.error()),
            _ => Ok(()),
        }
    }

    /// The toolpath and the notes, once every line is read: the motion after the last extrusion
    /// skipped, and a warning if E looks like filament length.
    fn finish(mut self) -> Result<(Toolpath, GcodeNotes), GcodeError> {
        let Some(last) = self.moves.iter().rposition(|m| m.kind == MoveKind::Print) else {
            // nothing deposits: there is no end of the print to skip after
            if let Some(h) = self.homed.first() {
                return Err(h.error());
            }
            return Ok((Toolpath::from_moves(self.moves)?, self.notes));
        };
        self.notes.after_last_extrusion = self.homed.len() + self.drop_travels_after(last);
        if self.pump.is_none() && self.opts.filament_diameter.is_none() {
            self.warn_if_e_looks_like_filament();
        }
        Ok((Toolpath::from_moves(self.moves)?, self.notes))
    }

    /// Drop the travels after the move `last`, keeping the dwells (time the deposit settles)
    /// where and when the last extrusion ended; the number of lines whose moves were dropped.
    fn drop_travels_after(&mut self, last: usize) -> usize {
        if self.moves[last + 1..].iter().all(|m| m.kind == MoveKind::Pause) {
            return 0; // nothing to drop: the moves stay as they are, to the bit
        }
        let tail = self.moves.split_off(last + 1);
        let lines = self.move_lines.split_off(last + 1);
        let (mut t, at) = (self.moves[last].t1, self.moves[last].to);
        let mut dropped = std::collections::BTreeSet::new();
        for (m, line) in tail.into_iter().zip(lines) {
            if m.kind == MoveKind::Pause {
                let t1 = t + m.duration();
                self.moves.push(Move { t0: t, t1, from: at, to: at, ..m });
                self.move_lines.push(line);
                t = t1;
            } else {
                dropped.insert(line);
            }
        }
        dropped.len()
    }

    /// Warn when the extrudate E lays per unit of path is far too little for a bead: E then
    /// likely counts filament length (an FDM slicer's file) and needs `filament_diameter`.
    fn warn_if_e_looks_like_filament(&mut self) {
        let prints = self.moves.iter().filter(|m| m.kind == MoveKind::Print);
        let (extrudate, path) = prints.fold((0.0, 0.0), |(e, p), m| (e + m.extrusion_speed * m.duration(), p + m.length()));
        let ratio = extrudate / path;
        if ratio < FILAMENT_LIKE_E_PER_PATH {
            self.notes.warnings.push(format!(
                "E lays {ratio:.3} m of extrudate per metre of path, a bead of {ratio:.3} times the outlet's area: \
                 if E counts filament length (as FDM slicers write it), give print.gcode_options.filament_diameter \
                 (E is then converted by volume)"
            ));
        }
    }

    fn execute(&mut self, words: &[Word]) -> Result<(), LineError> {
        // T is a command alone (a tool change) and the tool's index after an M-code (M104 S200 T0)
        let t_is_command = !words.iter().any(|w| matches!(w.letter, 'G' | 'M'));
        let is_command = |w: &Word| matches!(w.letter, 'G' | 'M') || (w.letter == 'T' && t_is_command);
        let mut commands = words.iter().filter(|w| is_command(w));
        let params: Vec<&Word> = words.iter().filter(|w| !is_command(w) && w.letter != 'N').collect();
        if let (Some(_), Some(e)) = (&self.pump, params.iter().find(|w| w.letter == 'E')) {
            return Err(LineError::Malformed(format!("{}: pump mode (print.gcode_options.flow_unit) takes the flow from the pump, not from E", e.text)));
        }
        let Some(cmd) = commands.next() else {
            let Some(first) = params.first() else {
                return Ok(()); // blank, comment or line number only
            };
            if let Some(pump) = self.pump.as_mut().filter(|_| params.iter().all(|w| w.letter == 'S')) {
                return pump.set_rate(value_of(&params, 'S')).map_err(LineError::Malformed); // the spindle word alone
            }
            check_params("", &params, KNOWN_LETTERS)?;
            return Err(LineError::Malformed(format!(
                "{} without a command (modal moves need their G0/G1)",
                first.text
            )));
        };
        if let Some(other) = commands.next() {
            return Err(LineError::Malformed(format!(
                "more than one command on the line ({} and {})",
                cmd.text, other.text
            )));
        }
        let unsupported =
            |reason: &str| Err(LineError::Unsupported { word: cmd.text.clone(), reason: reason.to_string() });
        let code = if cmd.value.fract() == 0.0 && cmd.value >= 0.0 { cmd.value as u32 } else { u32::MAX };
        // in pump mode a move may carry the spindle word S, setting the flow from this move on
        let spindle = if self.pump.is_some() { "S" } else { "" };
        match (cmd.letter, code) {
            ('G', 0 | 1) => {
                check_params(&cmd.text, &params, &format!("XYZEF{spindle}"))?;
                self.set_pump_rate(&params)?;
                self.linear_move(&cmd.text, code == 0, &params)
            }
            ('G', 2 | 3) => {
                check_params(&cmd.text, &params, &format!("XYZEFIJR{spindle}"))?;
                self.set_pump_rate(&params)?;
                self.arc_move(if code == 2 { Sense::Cw } else { Sense::Ccw }, &params)
            }
            ('M', m) if self.pump.as_ref().is_some_and(|p| p.is_command(m)) => {
                check_params(&cmd.text, &params, "S")?;
                let pump = self.pump.as_mut().expect("a pump command has a pump");
                pump.command(m, value_of(&params, 'S')).map_err(LineError::Malformed)
            }
            ('M', 3..=5) => unsupported("a spindle or pump; for a pump-driven printer set print.gcode_options.flow_unit (pump mode)"),
            ('G', 17) => check_params(&cmd.text, &params, ""),
            ('G', 18 | 19) => unsupported("arcs only in the XY plane (G17)"),
            ('G', 4) => {
                check_params(&cmd.text, &params, "PS")?;
                self.dwell(&params)
            }
            ('G', 20) => unsupported("inch units; remove G20 and set print.gcode_options.unit = 0.0254"),
            ('G', 21) => check_params(&cmd.text, &params, ""),
            ('G', 90 | 91) => {
                check_params(&cmd.text, &params, "")?;
                self.absolute_xyz = code == 90;
                Ok(())
            }
            ('M', 82 | 83) => {
                check_params(&cmd.text, &params, "")?;
                self.absolute_e = code == 82;
                Ok(())
            }
            ('G', 92) => {
                check_params(&cmd.text, &params, "XYZE")?;
                self.set_position(&params);
                Ok(())
            }
            ('M', 220 | 221) => {
                check_params(&cmd.text, &params, "S")?;
                let Some(percent) = value_of(&params, 'S').filter(|p| *p > 0.0) else {
                    return Err(LineError::Malformed(format!("{} needs S, a percentage > 0", cmd.text)));
                };
                match code {
                    220 => self.feed_factor = percent / 100.0,
                    _ => self.flow = percent / 100.0,
                }
                Ok(())
            }
            // firmware retraction: like a retraction and its un-retraction in E, it deposits nothing
            ('G', 10 | 11) if params.is_empty() => {
                self.notes.e_only += 1;
                Ok(())
            }
            ('M', m) if is_skipped_m(m) => self.skip(&cmd.text),
            ('T', 0) => self.skip(&cmd.text), // the one tool strand models
            _ => unsupported(""),
        }
    }

    fn skip(&mut self, command: &str) -> Result<(), LineError> {
        self.count_skipped(command);
        Ok(())
    }

    /// Pump mode: the S word of a move sets the flow from this move on.
    fn set_pump_rate(&mut self, params: &[&Word]) -> Result<(), LineError> {
        match self.pump.as_mut() {
            Some(pump) => pump.set_rate(value_of(params, 'S')).map_err(LineError::Malformed),
            None => Ok(()),
        }
    }

    /// G0/G1. `rapid` (G0) never extrudes.
    fn linear_move(&mut self, cmd: &str, rapid: bool, params: &[&Word]) -> Result<(), LineError> {
        self.set_feed(params)?;
        let target = self.target(params);
        if rapid && value_of(params, 'E').is_some() {
            return Err(LineError::Unsupported {
                word: format!("{cmd} E"),
                reason: "a rapid move cannot extrude; use G1".to_string(),
            });
        }
        let de = self.advance_e(params);
        let dist = (0..3).map(|i| (target[i] - self.machine[i]).powi(2)).sum::<f64>().sqrt();
        if dist == 0.0 {
            if de != 0.0 {
                // E alone (see the module doc): a retraction, the un-retraction restoring it, or
                // a prime in place beyond it; none deposits material
                self.notes.e_only += 1;
                if de < 0.0 {
                    self.retracted -= de;
                } else {
                    let restored = de.min(self.retracted);
                    self.retracted -= restored;
                    self.notes.primed += de - restored;
                }
            }
            return Ok(()); // a move to where the nozzle is: nothing moves
        }
        let duration = self.duration_of(dist);
        let (u, kind) = self.extrusion_over(de, duration);
        let to = self.world_of(target);
        self.push(duration, to, u, kind)?;
        self.machine = target;
        Ok(())
    }

    /// G2 (clockwise) / G3 (counter-clockwise) in the XY plane: to X Y (Z: a helix) round the
    /// centre at the start plus I, J, or of radius R (R < 0: the arc over half a turn). With I/J
    /// an end equal to the start in X, Y is a full circle. As G1: F sets the feed, which the
    /// nozzle keeps along the arc, and a net advance of E is extruded evenly over the arc's length.
    /// The arc becomes chords as a scenario `arc` does ([`Arc`]).
    fn arc_move(&mut self, sense: Sense, params: &[&Word]) -> Result<(), LineError> {
        self.set_feed(params)?;
        let target = self.target(params);
        let (from, to) = (self.world, self.world_of(target));
        let arc = match (value_of(params, 'I'), value_of(params, 'J'), value_of(params, 'R')) {
            (None, None, None) => return Err(LineError::Malformed("an arc needs I/J (the centre's offset from the start) or R (the radius)".into())),
            (Some(_), _, Some(_)) | (_, Some(_), Some(_)) => return Err(LineError::Malformed("an arc takes I/J or R, not both".into())),
            (None, None, Some(r)) => Arc::with_radius(from, to, self.opts.unit * r, sense),
            (i, j, None) => {
                // I/J are offsets from the start whatever G90/G91 (the standard, G91.1); a missing one is 0
                let center = [from[0] + self.opts.unit * i.unwrap_or(0.0), from[1] + self.opts.unit * j.unwrap_or(0.0)];
                let turns = u32::from(target[0] == self.machine[0] && target[1] == self.machine[1]);
                Arc::with_center(from, to, center, sense, turns)
            }
        }
        .map_err(|e| {
            let word = match e.input {
                ArcInput::Center | ArcInput::Turns => "I/J",
                ArcInput::Radius => "R",
                ArcInput::To => "X/Y",
            };
            LineError::Malformed(format!("arc {word}: {} (world metres)", e.message))
        })?;
        let de = self.advance_e(params);
        let duration = self.duration_of(arc.length() / self.opts.unit);
        let (u, kind) = self.extrusion_over(de, duration);
        let chords = arc.timed_points(self.t, duration).map_err(LineError::Malformed)?;
        for (t1, p) in chords {
            self.record(Move { t0: self.t, t1, from: self.world, to: p, extrusion_speed: u, kind });
        }
        self.machine = target;
        Ok(())
    }

    /// F: the feed rate from this move on.
    fn set_feed(&mut self, params: &[&Word]) -> Result<(), LineError> {
        if let Some(f) = value_of(params, 'F') {
            if !(f > 0.0) {
                return Err(LineError::Malformed(format!("feed rate F{f} must be > 0")));
            }
            self.feed = f;
        }
        Ok(())
    }

    /// The machine position X Y Z name, in the file's absolute or relative mode.
    fn target(&self, params: &[&Word]) -> [f64; 3] {
        let mut target = self.machine;
        for (axis, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            if let Some(v) = value_of(params, letter) {
                target[axis] = if self.absolute_xyz { v + self.offset[axis] } else { self.machine[axis] + v };
            }
        }
        target
    }

    /// Advance E by the move's E word, in the file's E mode; the advance (0 without E).
    fn advance_e(&mut self, params: &[&Word]) -> f64 {
        let Some(e) = value_of(params, 'E') else {
            return 0.0;
        };
        let de = if self.absolute_e { e - self.e } else { e };
        self.e = if self.absolute_e { e } else { self.e + e };
        de
    }

    /// Duration of a move of `dist` G-code units at the current feed [s].
    fn duration_of(&self, dist: f64) -> f64 {
        dist / (self.feed * self.feed_factor / 60.0)
    }

    /// Extrusion speed and kind of a moving move advancing E by `de` over `duration`; keeps
    /// track of what was retracted.
    fn extrusion_over(&mut self, de: f64, duration: f64) -> (f64, MoveKind) {
        if let Some(pump) = &self.pump {
            // the pump's flow, whatever the move (a running pump does not know G0 from G1)
            let u = pump.extrusion_speed() * self.flow;
            return (u, if u > 0.0 { MoveKind::Print } else { MoveKind::Travel });
        }
        // Only a net advance of E deposits material; a retraction while moving is a travel.
        let u = if de > 0.0 { de * self.flow * self.e_unit / duration } else { 0.0 };
        if de > 0.0 {
            self.retracted = 0.0;
        } else {
            self.retracted -= de; // retracted while moving (a wipe), restored in place later
        }
        (u, if u > 0.0 { MoveKind::Print } else { MoveKind::Travel })
    }

    /// World position [m] of machine coordinates.
    fn world_of(&self, target: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| self.opts.origin[i] + self.opts.unit * target[i])
    }

    /// G4 P<milliseconds> or G4 S<seconds>. A bare G4 (PrusaSlicer writes it to wait for the
    /// planned moves to finish) waits for nothing: strand's moves end when they are due.
    fn dwell(&mut self, params: &[&Word]) -> Result<(), LineError> {
        let seconds = match (value_of(params, 'P'), value_of(params, 'S')) {
            (Some(ms), None) => ms * 1e-3,
            (None, Some(s)) => s,
            (Some(_), Some(_)) => return Err(LineError::Malformed("G4 takes P (ms) or S (s), not both".to_string())),
            (None, None) => 0.0,
        };
        if seconds < 0.0 {
            return Err(LineError::Malformed(format!("negative dwell of {seconds} s")));
        }
        if seconds == 0.0 {
            return Ok(());
        }
        if let Some(pump) = &self.pump {
            // strand lays material only while the nozzle moves (see the module doc)
            self.notes.pumped_in_place += pump.flow() * self.flow * seconds;
        }
        self.push(seconds, self.world, 0.0, MoveKind::Pause)
    }

    /// G92: declare the current position's logical coordinates without moving; with no
    /// parameters every axis becomes 0.
    fn set_position(&mut self, params: &[&Word]) {
        let all = params.is_empty();
        for (axis, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            match value_of(params, letter) {
                Some(v) => self.offset[axis] = self.machine[axis] - v,
                None if all => self.offset[axis] = self.machine[axis],
                None => {}
            }
        }
        match value_of(params, 'E') {
            Some(v) => self.e = v,
            None if all => self.e = 0.0,
            None => {}
        }
    }

    fn push(&mut self, duration: f64, to: [f64; 3], u: f64, kind: MoveKind) -> Result<(), LineError> {
        let t1 = self.t + duration;
        if !(t1.is_finite() && t1 > self.t) {
            return Err(LineError::Malformed(format!(
                "move duration of {duration} s is not usable at t = {} s",
                self.t
            )));
        }
        self.record(Move { t0: self.t, t1, from: self.world, to, extrusion_speed: u, kind });
        Ok(())
    }

    /// Add a move read from the current line; the nozzle is then at its end.
    fn record(&mut self, m: Move) {
        (self.t, self.world) = (m.t1, m.to);
        if m.kind == MoveKind::Print {
            self.last_print_line = Some(self.line);
        }
        self.moves.push(m);
        self.move_lines.push(self.line);
    }
}

fn value_of(params: &[&Word], letter: char) -> Option<f64> {
    params.iter().find(|w| w.letter == letter).map(|w| w.value)
}

/// Reject parameters `cmd` does not take, telling unknown letters apart from misplaced ones.
fn check_params(cmd: &str, params: &[&Word], allowed: &str) -> Result<(), LineError> {
    match params.iter().find(|w| !allowed.contains(w.letter)) {
        None => Ok(()),
        Some(w) if !KNOWN_LETTERS.contains(w.letter) => Err(LineError::Malformed(format!("unknown word {}", w.text))),
        Some(w) => Err(LineError::Malformed(format!("{cmd} does not take {}", w.text))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Toolpath {
        parse_gcode(text, &GcodeOptions::default()).unwrap_or_else(|e| panic!("{e}"))
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * (1.0 + b.abs())
    }

    fn close3(a: [f64; 3], b: [f64; 3]) -> bool {
        (0..3).all(|i| close(a[i], b[i]))
    }

    /// Check one move: kind, [t0, t1), end position and extrusion speed.
    fn check(m: &Move, kind: MoveKind, t0: f64, t1: f64, to: [f64; 3], u: f64) {
        assert_eq!(m.kind, kind, "{m:?}");
        assert!(close(m.t0, t0) && close(m.t1, t1) && close3(m.to, to) && close(m.extrusion_speed, u), "{m:?}");
    }

    #[test]
    fn two_layer_file() {
        let text = "\
; two-layer test wall, millimetres
G21 ; millimetres
G90
M83 ; relative E
G1 Z10 F3000 ; to the first layer at 50 mm/s
G1 X100 E50 F6000 ; first layer: 100 mm at 100 mm/s, 50 mm of extrudate
G4 P500 ; let it set
G0 Z20 ; layer change at the modal 100 mm/s
G1 X0 E25 F3000 ; second layer back at 50 mm/s
G4 S0.25
G4 ; bare: wait for the moves to finish, no dwell
";
        let p = parse(text);
        let m = p.moves();
        assert_eq!(m.len(), 6);
        check(&m[0], MoveKind::Travel, 0.0, 0.2, [0.0, 0.0, 0.01], 0.0);
        check(&m[1], MoveKind::Print, 0.2, 1.2, [0.1, 0.0, 0.01], 0.05);
        check(&m[2], MoveKind::Pause, 1.2, 1.7, [0.1, 0.0, 0.01], 0.0);
        check(&m[3], MoveKind::Travel, 1.7, 1.8, [0.1, 0.0, 0.02], 0.0);
        check(&m[4], MoveKind::Print, 1.8, 3.8, [0.0, 0.0, 0.02], 0.0125);
        check(&m[5], MoveKind::Pause, 3.8, 4.05, [0.0, 0.0, 0.02], 0.0);
        let s = p.state_at(0.7);
        assert!(
            close3(s.position, [0.05, 0.0, 0.01]) && close3(s.velocity, [0.1, 0.0, 0.0]) && s.interval == 1,
            "{s:?}"
        );
        assert!(close(p.total_extruded_length(), 0.075));
        let layers = p.layers();
        assert_eq!(layers.len(), 2);
        assert!(close(layers[0].0, 0.01) && close(layers[0].1, 0.2) && close(layers[0].2, 1.2), "{layers:?}");
        assert!(close(layers[1].0, 0.02) && close(layers[1].1, 1.8) && close(layers[1].2, 3.8), "{layers:?}");
    }

    #[test]
    fn relative_moves_origin_and_start() {
        let opts = GcodeOptions { origin: [1.0, 2.0, 3.0], start: [5.0, 5.0, 0.0], ..GcodeOptions::default() };
        // (the travel is followed by an extrusion: travels after the last one are skipped)
        let p = parse_gcode("M83\nG91\nG1 X10 E5 F600\nG1 X10 E5\nG1 Y-5\nG1 Y-5 E1\n", &opts).unwrap();
        let m = p.moves();
        assert!(close3(m[0].from, [1.005, 2.005, 3.0]));
        check(&m[0], MoveKind::Print, 0.0, 1.0, [1.015, 2.005, 3.0], 0.005);
        check(&m[1], MoveKind::Print, 1.0, 2.0, [1.025, 2.005, 3.0], 0.005);
        check(&m[2], MoveKind::Travel, 2.0, 2.5, [1.025, 2.0, 3.0], 0.0);
        // Back to absolute: coordinates are the file's again.
        let p = parse_gcode("G91\nG1 X10 F600\nG90\nG1 X0\n", &opts).unwrap();
        assert!(close3(p.moves()[1].to, [1.0, 2.005, 3.0]));
    }

    #[test]
    fn absolute_e_with_g92() {
        let text = "M82\nG92 E0\nG1 X10 E2 F600\nG1 X20 E5\nG92 E0\nG1 X30 E1\nG1 X40 E0.5\nG1 E-1\nG1 X50 E0\n";
        let m = parse(text).moves().to_vec();
        assert_eq!(m.len(), 5); // the retraction in place moves nothing
        check(&m[0], MoveKind::Print, 0.0, 1.0, [0.01, 0.0, 0.0], 2e-3);
        check(&m[1], MoveKind::Print, 1.0, 2.0, [0.02, 0.0, 0.0], 3e-3);
        check(&m[2], MoveKind::Print, 2.0, 3.0, [0.03, 0.0, 0.0], 1e-3); // E counted from the reset
        check(&m[3], MoveKind::Travel, 3.0, 4.0, [0.04, 0.0, 0.0], 0.0); // retraction while moving
        check(&m[4], MoveKind::Print, 4.0, 5.0, [0.05, 0.0, 0.0], 1e-3); // E -1 -> 0 while moving
    }

    #[test]
    fn g92_resets_xyz_without_moving() {
        let m = parse("G1 X10 Y10 F600\nG92 X0\nG1 X5\nG92\nG1 Y5\n").moves().to_vec();
        assert_eq!(m.len(), 3);
        check(&m[1], MoveKind::Travel, m[0].t1, m[0].t1 + 0.5, [0.015, 0.01, 0.0], 0.0);
        check(&m[2], MoveKind::Travel, m[1].t1, m[1].t1 + 0.5, [0.015, 0.015, 0.0], 0.0);
    }

    #[test]
    fn comments_line_numbers_checksums_and_case() {
        let text = "%\nN1 G1 X10 F600*34 ; comment\r\nn2 g1 (inline; comment) y10 *12\n(full line comment)\n\n   ; indented comment\nG1X20Y20E1\nG1 X+20.0 Y.5 E-.5\nG1 X30 E1\n";
        let m = parse(text).moves().to_vec();
        assert_eq!(m.len(), 5);
        check(&m[0], MoveKind::Travel, 0.0, 1.0, [0.01, 0.0, 0.0], 0.0);
        check(&m[1], MoveKind::Travel, 1.0, 2.0, [0.01, 0.01, 0.0], 0.0);
        assert_eq!(m[2].kind, MoveKind::Print);
        check(&m[3], MoveKind::Travel, m[2].t1, m[2].t1 + 1.95, [0.02, 0.0005, 0.0], 0.0);
        // The default feed applies until the file sets one.
        let p = parse("G1 X50\n");
        assert!(close(p.end_time(), 1.0)); // 50 mm at 3000 mm/min
    }

    fn error(text: &str) -> GcodeError {
        match parse_gcode(text, &GcodeOptions::default()) {
            Err(e) => e,
            Ok(p) => panic!("accepted {text:?}: {:?}", p.moves()),
        }
    }

    #[test]
    fn unsupported_commands_name_line_and_word() {
        let head = "G21\n; setup\n";
        for (line, word) in [
            ("G20", "G20"),
            ("T1", "T1"),
            ("G18", "G18"),
            ("G1 X5\nG19", "G19"),
            ("g92.1", "G92.1"),
            ("G1 X5\nG28", "G28"),
            ("M3 S1000", "M3"),
            ("G10 P1 X5", "G10"),
            ("G0 X5 E1", "G0 E"),
        ] {
            match error(&format!("{head}{line}\n")) {
                GcodeError::Unsupported { line: n, word: w, text, .. } => {
                    assert_eq!((n, w.as_str()), (3 + line.matches('\n').count(), word), "{line}");
                    assert_eq!(text, line.rsplit('\n').next().unwrap_or(line));
                }
                e => panic!("{line}: expected Unsupported, got {e}"),
            }
        }
        assert_eq!(error("G21\n; setup\nG0 X1\nM42 P4 S255\n").to_string(), "gcode line 4: unsupported command M42 (\"M42 P4 S255\")");
        let msg = error("G1 X1\nG28 X0\n").to_string();
        assert!(msg.starts_with("gcode line 2: unsupported command G28 (\"G28 X0\"): homing"), "{msg}");
        assert!(error("G20\n").to_string().contains("inch"));
    }

    /// Issue 27 finding 12: what slicers write around the moves is skipped and counted; E alone
    /// deposits nothing; the flow and feed overrides scale the moves.
    #[test]
    fn machine_state_is_skipped_and_e_alone_deposits_nothing() {
        let text = "PRINT_START BED=60 EXTRUDER=200\nM107\nM104 S200\nM109 S200 T0\nM140 S60\nM117 Flow test: 5 mm/s, 0.8 mm\n\
                    M862.3 P \"MK3S\" ; printer model check\nG28 W\nT0\nG21\nG90\nM83\nG92 E0\nG4 S0\n\
                    G1 X10 E5 F600\nG1 E-0.8 F2100\nG0 X20\nG1 E0.8\nG1 X30 E5 F600\nG1 E-0.8\nG1 E2.8 ; un-retract and prime\n\
                    G10\nG11\nM84\nPRINT_END\n";
        let (p, notes) = parse_gcode_with_notes(text, &GcodeOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let m = p.moves();
        assert_eq!(m.len(), 3, "{m:?}");
        check(&m[0], MoveKind::Print, 0.0, 1.0, [0.01, 0.0, 0.0], 5e-3);
        check(&m[1], MoveKind::Travel, 1.0, 1.0 + 10.0 / 35.0, [0.02, 0.0, 0.0], 0.0);
        // the un-retraction restores the retraction: the next move deposits its own 5 E only
        check(&m[2], MoveKind::Print, m[1].t1, m[1].t1 + 1.0, [0.03, 0.0, 0.0], 5e-3);
        let n = |k: &str| notes.skipped.get(k).copied().unwrap_or(0);
        assert_eq!((n("PRINT_START"), n("PRINT_END"), n("M107"), n("M104"), n("M109"), n("M117"), n("M862.3"), n("G28"), n("T0"), n("M84")), (1, 1, 1, 1, 1, 1, 1, 1, 1, 1));
        assert!(notes.e_only == 6 && close(notes.primed, 2.0), "{notes:?}"); // 4 E moves + G10 + G11
        let line = notes.to_string();
        assert!(line.contains("skipped 11 machine-state") && line.contains("PRINT_START x1") && line.contains("2.000000 E units primed"), "{line}");
        // M221 scales what a move deposits, M220 the feed
        let m = parse("M83\nM221 S50\nM220 S200\nG1 X10 E5 F600\n").moves().to_vec();
        check(&m[0], MoveKind::Print, 0.0, 0.5, [0.01, 0.0, 0.0], 5e-3);
    }

    #[test]
    fn malformed_lines_name_line_and_problem() {
        let head = "G21\n; setup\n";
        for (line, needle) in [
            ("G1 X1.2.3", "bad number \"1.2.3\" after X"),
            ("G1 Xabc", "X must be followed by a number, found \"abc\""),
            ("G1 X", "X has no number"),
            ("G1 X1 X2", "X appears twice"),
            ("Q5", "unknown word Q5"),
            ("G1 X1 Q5", "unknown word Q5"),
            ("G1 X5 P3", "G1 does not take P3"),
            ("X10 Y5", "without a command"),
            ("G90 G21", "G appears twice"),
            ("G1 M82", "more than one command"),
            ("G1 X- ", "bad number \"-\""),
            ("G1 X1e", "E has no number"),
            ("G1 X10 F0", "feed rate F0 must be > 0"),
            ("G4 P1 S1", "not both"),
            ("G4 P-5", "negative dwell"),
            ("G1 (open comment X1", "unclosed"),
            ("G1 #1", "unexpected character '#'"),
            ("G1 X#1", "bad number \"#1\" after X"),
        ] {
            match error(&format!("{head}{line}\n")) {
                GcodeError::Malformed { line: 3, message, text } => {
                    assert!(message.contains(needle), "{line}: {message}");
                    assert_eq!(text, line.trim());
                }
                e => panic!("{line}: expected Malformed at line 3, got {e}"),
            }
        }
        assert_eq!(error("G1 X1\nG1 X1 X2\n").to_string(), "gcode line 2: X appears twice on the line (\"G1 X1 X2\")");
    }

    /// The circle of radius 10 mm about (10, 0) mm from the origin, in each G2/G3 form; the
    /// chords' ends lie on it and E is laid over the arc's length at the feed.
    #[test]
    fn arcs_in_every_form_give_the_same_circle() {
        let forms = [
            "G2 X0 Y0 I10 J0 E20 F600",              // one full clockwise turn, I/J
            "G3 X0 Y0 I10 J0 E20 F600",              // counter-clockwise
            "G2 X20 Y0 R10 E10 F600\nG2 X0 Y0 R10 E10", // two half circles, R form
            "G91\nG3 X20 Y0 R-10 E10 F600\nG3 X-20 Y0 I-10 E10", // relative end points, long-arc R
        ];
        let length = std::f64::consts::TAU * 10.0; // mm
        for form in forms {
            let p = parse(&format!("G21\nM83\n{form}\n"));
            let m = p.moves();
            assert!(m.len() >= 72, "{form}: {} chords", m.len());
            for mv in m {
                let r = (mv.to[0] - 0.01).hypot(mv.to[1]);
                assert!((r - 0.01).abs() < 1e-15, "{form}: {mv:?}");
                assert_eq!(mv.kind, MoveKind::Print);
                assert!(close(mv.extrusion_speed, 0.02 / (length / 10.0)), "{form}: {mv:?}");
            }
            assert!(close(p.end_time(), length / 10.0), "{form}: {}", p.end_time()); // 600 mm/min
            assert!(close(p.total_extruded_length(), 0.02), "{form}");
            assert_eq!(m.last().unwrap().to, [0.0; 3]);
            // G2 turns clockwise seen from above: from the circle's leftmost point it goes to +y
            let first_y = m[0].to[1];
            assert!(if form.contains("G2") { first_y > 0.0 } else { first_y < 0.0 }, "{form}");
        }
        // a helix: one turn rising 5 mm, travel (no E)
        let p = parse("G3 X0 Y0 Z5 I10 F600\n");
        assert!(close(p.end_time(), length.hypot(5.0) / 10.0) && p.moves().iter().all(|m| m.kind == MoveKind::Travel));
        assert!(close(p.moves().last().unwrap().to[2], 0.005));
        // the quarter from (0, 0) to (10, 10) about (10, 0), clockwise, I/J and R agree
        let (a, b) = (parse("G2 X10 Y10 I10 J0\n"), parse("G2 X10 Y10 R10\n"));
        assert_eq!(a.moves().len(), b.moves().len());
        assert!(a.moves().iter().zip(b.moves()).all(|(m, n)| close3(m.to, n.to) && close(m.t1, n.t1)));
    }

    #[test]
    fn arc_errors_name_the_line() {
        for (line, needle) in [
            ("G2 X10 Y0 R4", "arc R: |0.004| is less than half the chord"),
            ("G2 X10 Y0 I3 J0", "arc I/J: [0.003, 0.0] is not equidistant"),
            ("G2 X10 Y0", "needs I/J"),
            ("G2 X10 Y0 I5 R5", "not both"),
            ("G2 X0 Y0 R5", "full circle needs the centre form"),
            ("G2 X0 Y0 I0 J0", "zero radius"),
            ("G2 X10 Y0 I5 K1", "G2 does not take K1"),
        ] {
            match error(&format!("G21\n; setup\n{line}\n")) {
                GcodeError::Malformed { line: 3, message, .. } => assert!(message.contains(needle), "{line}: {message}"),
                e => panic!("{line}: expected Malformed at line 3, got {e}"),
            }
        }
        let msg = error("G1 X1\nG18\n").to_string();
        assert!(msg.starts_with("gcode line 2: unsupported command G18") && msg.contains("XY plane (G17)"), "{msg}");
        assert!(parse("G17\nG2 X10 Y0 R5\n").moves().len() > 1);
    }

    #[test]
    fn options_and_empty_files() {
        assert!(matches!(error("; nothing\n"), GcodeError::Toolpath(ToolpathError::Empty)));
        for opts in [
            GcodeOptions { unit: 0.0, ..GcodeOptions::default() },
            GcodeOptions { e_unit: Some(f64::NAN), ..GcodeOptions::default() },
            GcodeOptions { default_feed: -1.0, ..GcodeOptions::default() },
            GcodeOptions { origin: [f64::INFINITY, 0.0, 0.0], ..GcodeOptions::default() },
        ] {
            assert!(matches!(parse_gcode("G1 X1\n", &opts), Err(GcodeError::Option { .. })), "{opts:?}");
        }
        let msg =
            parse_gcode("G1 X1\n", &GcodeOptions { unit: 0.0, ..GcodeOptions::default() }).unwrap_err().to_string();
        assert_eq!(msg, "print.gcode_options.unit: unit = 0 must be finite and > 0");
        let option_error = |opts: GcodeOptions| match parse_gcode_for_outlet("G1 X1\n", &opts, 1e-4) {
            Err(GcodeError::Option { key, message }) => format!("{key}: {message}"),
            other => panic!("{opts:?}: {other:?}"),
        };
        let d = GcodeOptions::default();
        for (opts, want) in [
            (GcodeOptions { e_unit: Some(1e-3), filament_diameter: Some(1.75), ..d.clone() }, "filament_diameter: e_unit and filament_diameter both say what E counts"),
            (GcodeOptions { filament_diameter: Some(1.75), flow_unit: Some(1.0), ..d.clone() }, "flow_unit: filament_diameter and flow_unit both"),
            (GcodeOptions { filament_diameter: Some(-1.0), ..d.clone() }, "filament_diameter: filament_diameter = -1 must be finite and > 0"),
            (GcodeOptions { extruder_axis: 'X', ..d.clone() }, "extruder_axis: extruder_axis = 'X' must be one of the axis letters EABCDUVW"),
            (GcodeOptions { extruder_axis: 'U', flow_unit: Some(1.0), ..d.clone() }, "extruder_axis: pump mode (flow_unit) has no extruder axis"),
            (GcodeOptions { pump_on: Some("M3".into()), ..d.clone() }, "pump_on: pump_on switches the pump of pump mode"),
            (GcodeOptions { flow_unit: Some(1.0), pump_off: Some("M3".into()), ..d.clone() }, "pump_off: pump_off = \"M3\" is the same command as pump_on"),
            (GcodeOptions { flow_unit: Some(1.0), pump_on: Some("3".into()), ..d.clone() }, "pump_on: pump_on = \"3\" is not an M-code"),
        ] {
            let msg = option_error(opts);
            assert!(msg.starts_with(want), "{msg}");
        }
        // volumes need the outlet
        let msg = parse_gcode("G1 X1\n", &GcodeOptions { flow_unit: Some(1.0), ..d }).unwrap_err().to_string();
        assert!(msg.starts_with("print.gcode_options.flow_unit: flow_unit converts by volume"), "{msg}");
    }

    /// PrusaSlicer 2.7's object labels and other labelling and display commands are skipped and
    /// counted, their free text and all.
    #[test]
    fn labels_and_display_commands_are_skipped_and_counted() {
        let text = "M486 S0\nM486 AShape-Box (copy 1)\nM73 P0 R1\nM532 X0 L0\nM530 S1\nM531 two layers\nM75\nM83\n\
                    G1 X10 E10 F600\nM486 S-1\nM117 Layer 2 (50%\nM118 A1 done\nM300 S440 P200\nM77\n";
        let (p, notes) = parse_gcode_with_notes(text, &GcodeOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(p.moves().len(), 1);
        let n = |k: &str| notes.skipped.get(k).copied().unwrap_or(0);
        assert_eq!([n("M486"), n("M73"), n("M532"), n("M530"), n("M531"), n("M75"), n("M117"), n("M118"), n("M300"), n("M77")], [3, 1, 1, 1, 1, 1, 1, 1, 1, 1]);
        assert!(notes.to_string().starts_with("skipped 12 machine-state command(s) (temperatures, fans, object labels"), "{notes}");
    }

    /// Cura's end of print: the park and homing moves after the last extrusion are skipped with a
    /// note, the dwell kept; homing between extrusions still names itself and its line.
    #[test]
    fn motion_after_the_last_extrusion_is_skipped_with_a_note() {
        let text = "M83\nG1 X10 E10 F600\nG1 E-2\nG91\nG1 Z1\nG90\nG4 P500\nG1 X0 Y200 F3000 ; park\nG2 X10 Y200 R5\nG28 X0\nG27\nM84\n";
        let (p, notes) = parse_gcode_with_notes(text, &GcodeOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let m = p.moves();
        assert_eq!(m.len(), 2, "{m:?}");
        check(&m[1], MoveKind::Pause, 1.0, 1.5, [0.01, 0.0, 0.0], 0.0); // where and when the print ended
        assert_eq!(notes.after_last_extrusion, 5, "{notes:?}"); // Z lift, park, arc, G28, G27
        assert!(notes.to_string().contains("5 motion command(s) after the last extrusion skipped"), "{notes}");
        // a print ending on its last extrusion is left to the bit
        let plain = "M83\nG1 X10 E10 F600\nG4 P500\n";
        assert_eq!(parse(plain).moves(), parse(&format!("{plain}G28 X0\n")).moves());
        // homing between extrusions: an error at the homing line
        let msg = error("M83\nG1 X10 E10 F600\nG28 X0\nG1 X20 E10\n").to_string();
        assert!(msg.starts_with("gcode line 3: unsupported command G28 (\"G28 X0\"): homing, parking or probing between the first move and the last extrusion"), "{msg}");
        let msg = error("M83\nG1 X10 E10 F600\nG27\nG0 Z5\nG1 X20 E10\n").to_string();
        assert!(msg.starts_with("gcode line 3: unsupported command G27"), "{msg}");
        // an unsupported command after the last extrusion still names itself and its line
        assert_eq!(error("M83\nG1 X10 E10 F600\nM42 P4 S255\n").to_string(), "gcode line 3: unsupported command M42 (\"M42 P4 S255\")");
    }

    /// Comments as firmware reads them: Skeinforge's nested parentheses, `;` inside parentheses;
    /// an unclosed or stray parenthesis is refused naming the line.
    #[test]
    fn skeinforge_nested_comments_parse() {
        let text = "(<setting> carve Layer_Height_(mm): 0.4 </setting>)\n(<layer> 0.4 )\nG1 X10 F600 (<perimeter> outer (loop 1; of 2) )\n";
        assert_eq!(parse(text).moves().len(), 1);
        match error("G1 X10\nG1 X1 (a (b) c\n") {
            GcodeError::Malformed { line: 2, message, .. } => assert!(message.starts_with("unclosed '(' comment"), "{message}"),
            e => panic!("{e}"),
        }
        assert!(error("G1 X1 ) Y2\n").to_string().contains("')' at column 7 closes no '(' comment"));
    }

    /// A paste printer's Slic3r file drives its extruder on U.
    #[test]
    fn extruder_axis_names_the_e_word() {
        let opts = GcodeOptions { extruder_axis: 'U', ..GcodeOptions::default() };
        let u = parse_gcode("M83\nG1 X10 U5 F600\nG92 U0\n", &opts).unwrap();
        let e = parse("M83\nG1 X10 E5 F600\nG92 E0\n");
        assert_eq!(u.moves(), e.moves());
        let msg = parse_gcode("G1 X10 E5\n", &opts).unwrap_err().to_string();
        assert!(msg.contains("an E word, but the extruder is axis U (print.gcode_options.extruder_axis)"), "{msg}");
        let lower = GcodeOptions { extruder_axis: 'u', ..GcodeOptions::default() };
        assert_eq!(parse_gcode("M83\nG1 X10 u5 F600\n", &lower).unwrap().moves(), &e.moves()[..1]);
    }

    /// Filament-length E: converted by volume with filament_diameter; warned of without it.
    #[test]
    fn filament_diameter_converts_e_by_volume_and_its_absence_is_warned_of() {
        // 1.75 mm filament, 0.4 mm nozzle: 0.2 mm layers 0.45 mm wide need E 0.0374 per mm
        let fdm = "M83\nG1 X100 E3.74 F1800\n";
        let area = std::f64::consts::PI * 0.0004f64.powi(2) / 4.0;
        let opts = GcodeOptions { filament_diameter: Some(1.75), ..GcodeOptions::default() };
        let (p, notes) = parse_gcode_for_outlet(fdm, &opts, area).unwrap();
        let volume = p.total_extruded_length() * area;
        let want = 3.74e-3 * std::f64::consts::PI * 1.75e-3f64.powi(2) / 4.0;
        assert!((volume / want - 1.0).abs() < 1e-12, "{volume} vs {want} m³");
        assert!(notes.warnings.is_empty(), "{notes:?}");
        let (_, notes) = parse_gcode_for_outlet(fdm, &GcodeOptions::default(), area).unwrap();
        assert_eq!(notes.warnings.len(), 1);
        assert!(notes.warnings[0].starts_with("E lays 0.037 m of extrudate per metre of path") && notes.warnings[0].contains("filament_diameter"), "{:?}", notes.warnings);
        // extrudate E (a concrete printer's) is not warned of
        let (_, notes) = parse_gcode_with_notes("M83\nG1 X40 E44.8 F1800\n", &GcodeOptions::default()).unwrap();
        assert!(notes.warnings.is_empty());
    }

    /// Pump mode: M3/M5 (or M106/M107) switch the flow and S sets its rate; U = flow / area
    /// over every move while it runs.
    #[test]
    fn pump_mode_takes_the_flow_from_m_codes_and_the_spindle_word() {
        let area = 4e-4;
        let lpm = 1.0 / 60000.0; // m³/s per L/min
        let opts = GcodeOptions { flow_unit: Some(lpm), ..GcodeOptions::default() };
        let text = "G21\nM3 S1.2 ; 1.2 L/min\nG1 X100 F1800\nM5\nG0 Z10\nM3\nG1 X0 S2.4\nS0\nG1 Y10\nS1.2\nG4 P1000\nG1 Y0\n";
        let (p, notes) = parse_gcode_for_outlet(text, &opts, area).unwrap_or_else(|e| panic!("{e}"));
        let m = p.moves();
        let u = 1.2 * lpm / area;
        check(&m[0], MoveKind::Print, 0.0, 100.0 / 30.0, [0.1, 0.0, 0.0], u);
        assert_eq!((m[1].kind, m[2].kind, m[3].kind, m[4].kind), (MoveKind::Travel, MoveKind::Print, MoveKind::Travel, MoveKind::Pause));
        assert!(close(m[2].extrusion_speed, 2.0 * u));
        assert!(close(notes.pumped_in_place, 1.2 * lpm), "{notes:?}"); // 1 s of dwell
        let last = m.last().unwrap();
        assert!(last.kind == MoveKind::Print && close(last.extrusion_speed, u));
        // the volume is flow × time
        let volume = p.total_extruded_length() * area;
        let want = lpm * (1.2 * 100.0 / 30.0 + 2.4 * 100.0 / 30.0 + 1.2 * 10.0 / 30.0);
        assert!((volume / want - 1.0).abs() < 1e-12, "{volume} vs {want}");
        // fan-style codes, which are otherwise skipped as fans
        let fan = GcodeOptions { pump_on: Some("M106".into()), pump_off: Some("M107".into()), ..opts.clone() };
        let p = parse_gcode_for_outlet("M106 S1.2\nG1 X100 F1800\nM107\nG1 X0\nM106\nG1 X100\n", &fan, area).unwrap().0;
        let kinds: Vec<MoveKind> = p.moves().iter().map(|m| m.kind).collect();
        assert_eq!(kinds, [MoveKind::Print, MoveKind::Travel, MoveKind::Print]);
        // E in pump mode, and the pump's codes without pump mode, are refused
        let msg = parse_gcode_for_outlet("M3 S1\nG1 X1 E1\n", &opts, area).unwrap_err().to_string();
        assert!(msg.starts_with("gcode line 2: E1: pump mode"), "{msg}");
        let msg = parse_gcode_for_outlet("M5 S1\n", &opts, area).unwrap_err().to_string();
        assert!(msg.contains("M5 (pump_off) takes no S"), "{msg}");
        let msg = parse_gcode_for_outlet("G1 X1 S-1\n", &opts, area).unwrap_err().to_string();
        assert!(msg.contains("pump rate S-1 must be >= 0"), "{msg}");
        let msg = error("G1 X1\nM3 S1000\n").to_string();
        assert!(msg.starts_with("gcode line 2: unsupported command M3") && msg.contains("flow_unit"), "{msg}");
    }

    #[test]
    fn options_from_toml() {
        #[derive(serde::Deserialize)]
        struct Print {
            gcode: GcodeOptions,
        }
        let p: Print = toml::from_str("[gcode]\nunit = 0.0254\norigin = [0.1, 0.2, 0.0]\n").unwrap();
        assert_eq!(p.gcode, GcodeOptions { unit: 0.0254, origin: [0.1, 0.2, 0.0], ..GcodeOptions::default() });
        assert!(toml::from_str::<Print>("[gcode]\nunits = 0.001\n").is_err());
    }
}
