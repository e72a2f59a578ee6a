//! What slicers and firmware write around the moves: comments as firmware reads them, and the
//! commands the G-code import skips because they neither move the nozzle nor lay material.
//!
//! Comments (the rule of LinuxCNC and of RepRap firmware with parenthesised comments, which
//! Skeinforge relies on):
//! - `;` starts a comment that runs to the end of the line;
//! - `(` starts a comment that runs to the `)` matching it, nested pairs counted, so Skeinforge's
//!   `(<setting> carve Layer_Height_(mm): 0.4 </setting>)` is one comment; inside it `;` and `*`
//!   are text;
//! - outside comments, `*` starts the checksum, which ends the line's code;
//! - a parenthesised comment must close on its line, and a `)` needs its `(`: either mistake is
//!   refused, naming it, because guessing where the comment ends could swallow a move or read
//!   comment text as one.

/// The line's code with its comments and checksum removed (a comment becomes a space: it
/// separates words), or what is wrong with its parentheses.
pub fn strip_comments(raw: &str) -> Result<String, String> {
    let mut code = String::with_capacity(raw.len());
    let mut depth = 0usize;
    for (i, c) in raw.char_indices() {
        match (depth, c) {
            (_, '(') => depth += 1,
            (0, ')') => return Err(format!("')' at column {} closes no '(' comment", i + 1)),
            (_, ')') => {
                depth -= 1;
                if depth == 0 {
                    code.push(' ');
                }
            }
            (0, ';' | '*') => break, // the rest is a comment or the checksum
            (0, c) => code.push(c),
            _ => {} // inside a parenthesised comment
        }
    }
    if depth > 0 {
        return Err(format!(
            "unclosed '(' comment: {depth} '(' without its ')' (a parenthesised comment runs to its matching ')' on the same line; nested pairs count)"
        ));
    }
    Ok(code)
}

/// The line's first word, upper-cased, outside comments (before a `;` if the parentheses do not
/// balance: a message's free text may hold any character).
pub fn first_word(raw: &str) -> Option<String> {
    let code = strip_comments(raw).unwrap_or_else(|_| raw.split(';').next().unwrap_or("").to_string());
    let first: String = code.trim_start().chars().take_while(|c| !c.is_whitespace()).collect();
    (!first.is_empty()).then(|| first.to_ascii_uppercase())
}

/// A line that is not made of G-code words and is skipped whole: a firmware macro or extended
/// command (`PRINT_START EXTRUDER=200`, `SET_VELOCITY_LIMIT ...`, named by a word of two or more
/// letters), a machine-state or labelling M-code (whose words may lack numbers, as Cura's
/// `M84 X Y E`, or hold free text, as `M486 AShape-Box` or `M117 Layer 2`) or a printer model
/// check (M862.x). Its name, upper-cased, for the note; None for any other line.
pub fn free_text_command(raw: &str) -> Option<String> {
    let first = first_word(raw)?;
    let mut chars = first.chars();
    let macro_name = matches!((chars.next(), chars.next()), (Some(a), Some(b)) if a.is_ascii_alphabetic() && (b.is_ascii_alphabetic() || b == '_'))
        && first.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    let skipped_m = first.strip_prefix('M').and_then(|n| n.parse::<u32>().ok()).is_some_and(is_skipped_m);
    let model_check = first.strip_prefix("M862.").is_some_and(|r| !r.is_empty() && r.chars().all(|c| c.is_ascii_digit()));
    (macro_name || skipped_m || model_check).then_some(first)
}

/// Whether M`code` is skipped: a machine-state or a labelling and display command.
pub fn is_skipped_m(code: u32) -> bool {
    MACHINE_STATE_M.contains(&code) || LABEL_AND_DISPLAY_M.contains(&code)
}

/// M-codes that set machine state only: temperatures (M104, M109, M140, M190, M141, M191,
/// M116), fans (M106, M107), reports (M105, M114, M115, M31), steppers (M17, M18, M84), waiting
/// for moves to finish (M400), motion limits and tuning (M201, M203, M204, M205, M900, M907),
/// stored settings (M500-M503) and the bed mesh switch (M420).
const MACHINE_STATE_M: &[u32] =
    &[17, 18, 31, 84, 104, 105, 106, 107, 109, 114, 115, 116, 140, 141, 190, 191, 201, 203, 204, 205, 400, 420, 500, 501, 502, 503, 900, 907];

/// M-codes that label the print or talk to the printer's display or host, and change nothing
/// printed: object labels for cancelling objects (M486, PrusaSlicer 2.7), messages (M117 on the
/// display, M118 to the host), progress (M73, and M532 on Prusa's display), print job state for
/// the display and host (M530 printing flag, M531 file name, M75/M76/M77 print timer start,
/// pause, stop) and sounds (M300).
const LABEL_AND_DISPLAY_M: &[u32] = &[73, 75, 76, 77, 117, 118, 300, 486, 530, 531, 532];

/// G-codes that home, park or probe: skipped before the first move (the nozzle then starts at
/// `start`, where homing leaves it) and after the last extrusion (the print is laid), refused in
/// between (the nozzle would go where strand does not know): G27 park, G28 home, G29 probe the
/// bed, G30 probe one point, G80 mesh bed levelling.
pub const HOMING_G: &[u32] = &[27, 28, 29, 30, 80];

/// Whether the line's first word is one of `HOMING_G` (homing may carry firmware-specific words,
/// as Prusa's `G28 W`, so the line is judged by its first word).
pub fn homing_command(raw: &str) -> Option<String> {
    first_word(raw).filter(|w| HOMING_G.iter().any(|g| *w == format!("G{g}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_as_firmware_reads_them() {
        let code = |s: &str| strip_comments(s).unwrap_or_else(|e| panic!("{s}: {e}"));
        assert_eq!(code("G1 X1 ; move (it"), "G1 X1 ");
        assert_eq!(code("G1 (a; b * c) X1*12"), "G1   X1");
        // Skeinforge: nested parentheses are one comment
        assert_eq!(code("(<setting> carve Layer_Height_(mm): 0.4 </setting>)").trim(), "");
        assert_eq!(code("G1 X1 ((a) (b (c))) Y2"), "G1 X1   Y2");
        let err = strip_comments("G1 X1 (open (nested) comment").unwrap_err();
        assert!(err.starts_with("unclosed '(' comment: 1 '('") && err.contains("matching ')'"), "{err}");
        assert!(strip_comments("G1 X1 ((two").unwrap_err().contains("2 '('"));
        assert_eq!(strip_comments("G1 X1) Y2").unwrap_err(), "')' at column 6 closes no '(' comment");
        assert_eq!(first_word("(<layer> 0.4 ) G1 X1").as_deref(), Some("G1"));
        assert_eq!(first_word("M117 Printing (50%").as_deref(), Some("M117"));
    }

    #[test]
    fn labels_and_display_are_skipped_whole() {
        for line in ["M486 S0", "M486 AShape-Box (copy 1)", "M486 S-1", "M532 X50 L2", "M73 P50 R10", "M117 Layer 2 of 5", "M118 E1 done", "M300 S440 P200", "M530 S1", "M531 two_layers", "M75", "M77"] {
            assert!(free_text_command(line).is_some(), "{line}");
        }
        assert_eq!(free_text_command("M486 AShape-Box").as_deref(), Some("M486"));
        assert_eq!(free_text_command("G1 X1"), None);
        assert_eq!(free_text_command("M3 S1"), None);
        assert_eq!(homing_command("G28 X0").as_deref(), Some("G28"));
        assert_eq!(homing_command("G27 ; park").as_deref(), Some("G27"));
        assert_eq!(homing_command("G2 X1"), None);
    }
}
