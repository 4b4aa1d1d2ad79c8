//! Miscellaneous functions (`M` words) and `FUNCTION` blocks, classified as the TNC
//! means them: honoured (M91, M92 where the machine names its reference point),
//! accepted without effect (stops, spindle, coolant: nothing a probe cycle moves
//! by), or refused at their line because they change what a move means and are not
//! implemented here (M128 TCPM, M126 shortest path, M118 handwheel, ...). An M number
//! not in the table is refused too: nothing is skipped without a word.

/// What probebridge does with one M function.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MClass {
    /// M91: the block's coordinates are machine coordinates.
    MachineCoordinates,
    /// M92: the block's coordinates are relative to the machine's reference point
    /// (`[cycles] m92_reference`).
    ReferencePoint,
    /// Accepted; nothing to do for a probing program.
    NoEffect(&'static str),
    /// Changes what a move means; not implemented, so refused.
    Refused(&'static str),
}

/// M functions accepted without effect: (number, what it does on the TNC).
pub const NO_EFFECT: &[(u32, &str)] = &[
    (0, "program stop"),
    (1, "optional program stop"),
    (2, "end of program"),
    (3, "spindle on clockwise"),
    (4, "spindle on counterclockwise"),
    (5, "spindle stop"),
    (8, "coolant on"),
    (9, "coolant off"),
    (30, "end of program"),
    (102, "cancels M101 (never active here)"),
    (106, "cancels M105 (never active here)"),
    (108, "cancels M107 (never active here)"),
    (111, "cancels M109/M110 (never active here)"),
    (115, "cancels M114 (never active here)"),
    (
        117,
        "cancels M116 (feed of rotary axes in deg/min, as here)",
    ),
    (
        127,
        "cancels M126 (rotary axes take the programmed way, as here)",
    ),
    (129, "cancels M128 (TCPM off, as here)"),
];

/// M functions refused by name: (number, what it would change).
pub const REFUSED: &[(u32, &str)] = &[
    (6, "tool change"),
    (13, "spindle on clockwise and coolant on"),
    (14, "spindle on counterclockwise and coolant on"),
    (89, "modal cycle call"),
    (94, "reduce the display of a rotary axis below 360 deg"),
    (97, "machine small contour steps"),
    (98, "open contours completely"),
    (99, "cycle call"),
    (101, "automatic tool change when the tool life expires"),
    (103, "reduce the feed when plunging"),
    (104, "reactivate the last datum set by hand"),
    (105, "second kv factor"),
    (107, "suppress the error message for replacement tools"),
    (109, "constant feed at the tool cutting edge on arcs"),
    (110, "feed on inside arcs"),
    (112, "insert rounding arcs"),
    (114, "compensate the machine geometry with tilted axes"),
    (116, "feed of rotary axes in mm/min"),
    (118, "handwheel superimposition"),
    (120, "look-ahead of radius-compensated contours"),
    (124, "ignore points for rounding"),
    (126, "shortest path of rotary axes"),
    (128, "TCPM: keep the tool tip when tilting axes move"),
    (130, "move in the untilted coordinate system"),
    (136, "feed in mm per spindle revolution"),
    (138, "select tilting axes"),
    (140, "retract in the tool axis"),
    (141, "suppress touch probe monitoring"),
    (143, "delete the basic rotation"),
    (
        144,
        "compensate the kinematics for actual/nominal positions",
    ),
    (148, "retract automatically at NC stop"),
    (150, "suppress limit switch messages"),
];

/// The class of M function `n`; `None`: not known here (refused as unknown).
pub fn classify(n: u32) -> Option<MClass> {
    match n {
        91 => Some(MClass::MachineCoordinates),
        92 => Some(MClass::ReferencePoint),
        _ => NO_EFFECT
            .iter()
            .find(|(m, _)| *m == n)
            .map(|(_, what)| MClass::NoEffect(what))
            .or_else(|| {
                REFUSED
                    .iter()
                    .find(|(m, _)| *m == n)
                    .map(|(_, what)| MClass::Refused(what))
            }),
    }
}

/// `M91` -> 91; `None` when the word is not an M function.
pub fn m_number(word: &str) -> Option<u32> {
    let rest = word.strip_prefix(['M', 'm'])?;
    if rest.is_empty() || !rest.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    rest.parse().ok()
}

/// The M functions of a block that set its coordinate system.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BlockMFunctions {
    /// M91 in the block.
    pub m91: bool,
    /// M92 in the block.
    pub m92: bool,
}

/// Checks every M word of a block (`L ... M91`, `M30`): the coordinate functions it
/// sets, or why a word cannot run. `m92_reference`: whether the machine names the
/// point M92 refers to.
pub fn check_words(code: &str, m92_reference: bool) -> Result<BlockMFunctions, String> {
    let mut found = BlockMFunctions::default();
    for w in code.split_whitespace() {
        let Some(n) = m_number(w) else { continue };
        match classify(n) {
            Some(MClass::MachineCoordinates) => found.m91 = true,
            Some(MClass::ReferencePoint) if m92_reference => found.m92 = true,
            Some(MClass::ReferencePoint) => {
                return Err(format!(
                    "{w}: M92 (coordinates relative to the machine's reference point) is refused: the machine configuration names no reference point ([cycles] m92_reference = [X, Y, Z]); use M91 for machine coordinates"
                ))
            }
            Some(MClass::NoEffect(_)) => {}
            Some(MClass::Refused(what)) => {
                return Err(format!(
                    "{w} ({what}) changes what the program's moves mean and is not implemented: refused; nothing moved"
                ))
            }
            None => {
                return Err(format!(
                    "{w}: unknown M function: refused (accepted: M91, M92 with a reference point, {})",
                    NO_EFFECT
                        .iter()
                        .map(|(m, _)| format!("M{m}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            }
        }
    }
    if found.m91 && found.m92 {
        return Err(
            "M91 and M92 in one block: the coordinates can refer to one system only".into(),
        );
    }
    Ok(found)
}

/// What a `FUNCTION ...` block does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FunctionBlock {
    /// `FUNCTION MODE MILL`: milling mode, the mode the probe cycles run in.
    ModeMill,
    /// `FUNCTION MODE TURN`: turning mode; the probe cycles are refused after it.
    ModeTurn,
}

/// `FUNCTION MODE MILL|TURN`; anything else (`FUNCTION TCPM`, `FUNCTION PARAXCOMP`,
/// ...) is refused with its name.
pub fn function_block(code: &str) -> Result<FunctionBlock, String> {
    let words: Vec<String> = code
        .split_whitespace()
        .map(str::to_ascii_uppercase)
        .collect();
    let w = |i: usize| words.get(i).map(String::as_str);
    match (w(1), w(2), w(3)) {
        (Some("MODE"), Some("MILL"), None) => Ok(FunctionBlock::ModeMill),
        (Some("MODE"), Some("TURN"), None) => Ok(FunctionBlock::ModeTurn),
        (Some("MODE"), _, _) => Err(format!(
            "{}: expected FUNCTION MODE MILL or FUNCTION MODE TURN",
            code.trim()
        )),
        (Some("TCPM"), _, _) => Err(
            "FUNCTION TCPM (tool centre point management) is refused: the touch-probe cycles need it off (as M128), and probebridge does not implement it; nothing moved"
                .into(),
        ),
        (Some(name), _, _) => Err(format!(
            "FUNCTION {name} changes what the program's moves mean and is not implemented: refused (FUNCTION MODE MILL and FUNCTION MODE TURN run); nothing moved"
        )),
        (None, _, _) => Err("FUNCTION without a name".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_number_has_one_class() {
        for (n, _) in NO_EFFECT.iter().chain(REFUSED.iter()) {
            let in_both =
                NO_EFFECT.iter().any(|(m, _)| m == n) && REFUSED.iter().any(|(m, _)| m == n);
            assert!(!in_both, "M{n} in both tables");
            assert!(![91, 92].contains(n));
        }
        assert_eq!(classify(91), Some(MClass::MachineCoordinates));
        assert!(matches!(classify(128), Some(MClass::Refused(w)) if w.contains("TCPM")));
        assert_eq!(classify(7), None);
    }

    #[test]
    fn words_of_a_block() {
        let m = check_words("L Z+150 R0 FMAX M91", false).unwrap();
        assert!(m.m91 && !m.m92);
        assert!(check_words("M30", false).unwrap() == BlockMFunctions::default());
        assert!(check_words("L Z+1 M92", true).unwrap().m92);
        let e = check_words("L Z+1 M92", false).unwrap_err();
        assert!(e.contains("m92_reference"), "{e}");
        for (code, name) in [
            ("L X+1 M128", "M128"),
            ("M126", "M126"),
            ("L Z+1 M140", "M140"),
        ] {
            let e = check_words(code, false).unwrap_err();
            assert!(e.starts_with(name) && e.contains("refused"), "{e}");
        }
        let e = check_words("M77", false).unwrap_err();
        assert!(e.contains("unknown M function"), "{e}");
        assert!(check_words("L Z+1 M91 M92", true).is_err());
    }

    #[test]
    fn function_blocks() {
        assert_eq!(
            function_block("FUNCTION MODE MILL"),
            Ok(FunctionBlock::ModeMill)
        );
        assert_eq!(
            function_block("function mode turn"),
            Ok(FunctionBlock::ModeTurn)
        );
        assert!(function_block("FUNCTION TCPM F TCP AXIS POS PATHCTRL AXIS")
            .unwrap_err()
            .contains("FUNCTION TCPM"));
        assert!(function_block("FUNCTION PARAXCOMP DISPLAY W")
            .unwrap_err()
            .contains("FUNCTION PARAXCOMP"));
        assert!(function_block("FUNCTION MODE DRESS").is_err());
    }
}
