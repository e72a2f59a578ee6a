//! Observables: functions of the particle state at one time.
