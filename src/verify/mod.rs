//! The verification suite: closed-form and experimental references.
pub mod analytic;

pub fn run_suite(_quick: bool, _json: bool, _case: Option<&str>, _threads: Option<usize>) -> Result<bool, String> {
    Err("verify: not yet".into())
}
