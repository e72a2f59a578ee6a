//! Pump mode of the G-code import: concrete printers rarely count E. A pump is switched on and
//! off by M-codes and runs at a set flow, given by an S word (a spindle speed on CNC firmware, a
//! fan PWM on M106-style setups).
//!
//! The rule: the flow is `S × flow_unit` [m³/s] while the pump is on, and 0 while it is off.
//! `pump_on` (default `M3`) switches it on, its S (if any) setting the rate; `pump_off`
//! (default `M5`) switches it off; S on a move line or alone on a line sets the rate from then
//! on (the spindle word); S0 stops the flow without switching the pump off. Every move the
//! nozzle makes while material flows deposits `flow × duration` — G0 too, since a running pump
//! does not know the move is rapid — and what flows while the nozzle stands still (a dwell with
//! the pump on, a prime) is dropped and counted in the note, as a prime of E is.

/// The pump's codes and its state while a file is read.
#[derive(Clone, Debug)]
pub struct Pump {
    /// M-code numbers that switch it on and off.
    pub on_code: u32,
    pub off_code: u32,
    /// m³/s of material per unit of S.
    pub flow_unit: f64,
    /// Area of the nozzle's outlet the flow passes [m²].
    pub outlet_area: f64,
    running: bool,
    /// The last S [S units].
    rate: f64,
}

impl Pump {
    /// The pump named by the options' `pump_on` / `pump_off` (None: `M3` / `M5`), off, at rate 0;
    /// or the key and what is wrong with it.
    pub fn new(on: Option<&str>, off: Option<&str>, flow_unit: f64, outlet_area: f64) -> Result<Pump, (&'static str, String)> {
        let on_code = m_code("pump_on", on.unwrap_or("M3"))?;
        let off_code = m_code("pump_off", off.unwrap_or("M5"))?;
        if on_code == off_code {
            return Err(("pump_off", format!("pump_off = \"M{off_code}\" is the same command as pump_on")));
        }
        Ok(Pump { on_code, off_code, flow_unit, outlet_area, running: false, rate: 0.0 })
    }

    /// Whether M`code` is one of the pump's commands.
    pub fn is_command(&self, code: u32) -> bool {
        code == self.on_code || code == self.off_code
    }

    /// Apply the pump's command M`code` with its S word, if any.
    pub fn command(&mut self, code: u32, s: Option<f64>) -> Result<(), String> {
        if code == self.off_code {
            if s.is_some() {
                return Err(format!("M{code} (pump_off) takes no S"));
            }
            self.running = false;
            return Ok(());
        }
        self.running = true;
        self.set_rate(s)
    }

    /// S: the rate from now on (None: unchanged).
    pub fn set_rate(&mut self, s: Option<f64>) -> Result<(), String> {
        match s {
            Some(s) if s < 0.0 => Err(format!("pump rate S{s} must be >= 0")),
            Some(s) => {
                self.rate = s;
                Ok(())
            }
            None => Ok(()),
        }
    }

    /// The flow now [m³/s].
    pub fn flow(&self) -> f64 {
        if self.running {
            self.rate * self.flow_unit
        } else {
            0.0
        }
    }

    /// The speed of material through the outlet now (U) [m/s].
    pub fn extrusion_speed(&self) -> f64 {
        self.flow() / self.outlet_area
    }
}

/// The number of an option's M-code (`"M3"` -> 3).
fn m_code(key: &'static str, text: &str) -> Result<u32, (&'static str, String)> {
    text.trim()
        .strip_prefix(['M', 'm'])
        .and_then(|n| n.parse::<u32>().ok())
        .ok_or_else(|| (key, format!("{key} = {text:?} is not an M-code such as \"M3\"")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn switches_and_rates() {
        let mut p = Pump::new(None, None, 2.0, 0.5).unwrap();
        assert_eq!(p.flow(), 0.0);
        p.set_rate(Some(3.0)).unwrap();
        assert_eq!(p.flow(), 0.0); // off: S only sets the rate
        p.command(3, None).unwrap();
        assert_eq!((p.flow(), p.extrusion_speed()), (6.0, 12.0));
        p.command(3, Some(1.0)).unwrap();
        assert_eq!(p.flow(), 2.0);
        p.set_rate(Some(0.0)).unwrap();
        assert_eq!(p.flow(), 0.0);
        p.set_rate(Some(1.0)).unwrap();
        p.command(5, None).unwrap();
        assert_eq!(p.flow(), 0.0);
        assert!(p.command(5, Some(1.0)).unwrap_err().contains("takes no S"));
        assert!(p.set_rate(Some(-1.0)).unwrap_err().contains(">= 0"));
        let fan = Pump::new(Some("M106"), Some("m107"), 1.0, 1.0).unwrap();
        assert!(fan.is_command(106) && fan.is_command(107) && !fan.is_command(3));
        assert_eq!(Pump::new(Some("S"), None, 1.0, 1.0).unwrap_err(), ("pump_on", "pump_on = \"S\" is not an M-code such as \"M3\"".to_string()));
        assert_eq!(Pump::new(Some("M5"), None, 1.0, 1.0).unwrap_err().0, "pump_off");
    }
}
