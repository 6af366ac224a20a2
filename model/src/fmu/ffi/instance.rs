//! One instance of an FMU: the FMI functions of its life (initialisation, values, events,
//! states, steps), each status checked, its log messages kept.

use super::*;

/// What the FMU reports at the end of an event iteration.
#[derive(Debug, Clone, Copy, Default)]
pub struct EventUpdate {
    pub again: bool,
    pub terminate: bool,
    pub values_changed: bool,
    pub next_event_time: Option<f64>,
}

/// One instance of an FMU; freed on drop.
pub struct Instance {
    pub(super) lib: Arc<Library>,
    pub(super) handle: Ptr,
    pub(super) sink: Box<LogSink>,
    pub(super) _callbacks: Option<Box<Fmi2Callbacks>>,
}

macro_rules! call {
    ($self:ident, $ty:ty, $name2:literal, $name3:literal, |$f:ident| $call:expr) => {{
        let (slot, name) = match $self.lib.version {
            FmiVersion::V2 => (const { slot($name2) }, $name2),
            FmiVersion::V3 => (const { slot($name3) }, $name3),
        };
        let $f: $ty = $self.lib.symbol(slot, name)?;
        // SAFETY: a live instance and arguments as the standard declares them.
        let status = unsafe { $call };
        $self.check(name, status)
    }};
}

impl Instance {
    /// The FMU's messages so far, oldest first.
    pub fn log(&self) -> Vec<String> {
        self.sink
            .messages
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    pub(super) fn failure(&self, function: &str, status: c_int) -> FmuError {
        FmuError::Call {
            function: function.to_string(),
            status: status_name(status),
            log: self.log(),
        }
    }

    fn check(&self, function: &str, status: c_int) -> Result<(), FmuError> {
        // OK and Warning go on; Discard, Error and Fatal end the simulation.
        if status <= 1 {
            Ok(())
        } else {
            Err(self.failure(function, status))
        }
    }

    pub fn reset(&mut self) -> Result<(), FmuError> {
        self.sink
            .messages
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clear();
        let h = self.handle;
        call!(self, Fmi2Status0, "fmi2Reset", "fmi3Reset", |f| f(h))
    }

    /// Set up the experiment and enter initialisation mode.
    pub fn enter_initialization(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Result<(), FmuError> {
        let h = self.handle;
        let (tol_defined, tol) = (tolerance.is_some(), tolerance.unwrap_or(0.0));
        let (stop_defined, stop) = (stop.is_some(), stop.unwrap_or(0.0));
        match self.lib.version {
            FmiVersion::V2 => {
                let setup: Fmi2SetupExperiment = sym!(self.lib, "fmi2SetupExperiment")?;
                // SAFETY: as above.
                let status = unsafe {
                    setup(
                        h,
                        tol_defined as c_int,
                        tol,
                        start,
                        stop_defined as c_int,
                        stop,
                    )
                };
                self.check("fmi2SetupExperiment", status)?;
                call!(self, Fmi2Status0, "fmi2EnterInitializationMode", "", |f| f(
                    h
                ))
            }
            FmiVersion::V3 => call!(
                self,
                Fmi3EnterInit,
                "",
                "fmi3EnterInitializationMode",
                |f| f(h, tol_defined, tol, start, stop_defined, stop)
            ),
        }
    }

    pub fn exit_initialization(&mut self) -> Result<(), FmuError> {
        let h = self.handle;
        call!(
            self,
            Fmi2Status0,
            "fmi2ExitInitializationMode",
            "fmi3ExitInitializationMode",
            |f| f(h)
        )
    }

    pub fn set_reals(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        let h = self.handle;
        let n = vrs.len();
        match self.lib.version {
            FmiVersion::V2 => call!(self, Fmi2SetReals, "fmi2SetReal", "", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_ptr()
            )),
            FmiVersion::V3 => call!(self, Fmi3SetF64, "", "fmi3SetFloat64", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_ptr(),
                n
            )),
        }
    }

    pub fn set_integers(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        let h = self.handle;
        let n = vrs.len();
        match self.lib.version {
            FmiVersion::V2 => call!(self, Fmi2SetInts, "fmi2SetInteger", "", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_ptr()
            )),
            FmiVersion::V3 => call!(self, Fmi3SetI32, "", "fmi3SetInt32", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_ptr(),
                n
            )),
        }
    }

    pub fn set_booleans(&mut self, vrs: &[u32], values: &[bool]) -> Result<(), FmuError> {
        let h = self.handle;
        let n = vrs.len();
        match self.lib.version {
            FmiVersion::V2 => {
                let ints: Vec<c_int> = values.iter().map(|&b| c_int::from(b)).collect();
                call!(self, Fmi2SetInts, "fmi2SetBoolean", "", |f| f(
                    h,
                    vrs.as_ptr(),
                    n,
                    ints.as_ptr()
                ))
            }
            FmiVersion::V3 => call!(self, Fmi3SetBool, "", "fmi3SetBoolean", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_ptr(),
                n
            )),
        }
    }

    pub fn get_reals(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), FmuError> {
        let h = self.handle;
        let n = vrs.len();
        match self.lib.version {
            FmiVersion::V2 => call!(self, Fmi2Reals, "fmi2GetReal", "", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_mut_ptr()
            )),
            FmiVersion::V3 => call!(self, Fmi3GetF64, "", "fmi3GetFloat64", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_mut_ptr(),
                n
            )),
        }
    }

    pub fn get_integers(&mut self, vrs: &[u32], values: &mut [i32]) -> Result<(), FmuError> {
        let h = self.handle;
        let n = vrs.len();
        match self.lib.version {
            FmiVersion::V2 => call!(self, Fmi2Ints, "fmi2GetInteger", "", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_mut_ptr()
            )),
            FmiVersion::V3 => call!(self, Fmi3GetI32, "", "fmi3GetInt32", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_mut_ptr(),
                n
            )),
        }
    }

    pub fn get_booleans(&mut self, vrs: &[u32], values: &mut [bool]) -> Result<(), FmuError> {
        let h = self.handle;
        let n = vrs.len();
        match self.lib.version {
            FmiVersion::V2 => {
                let mut ints = vec![0; n];
                call!(self, Fmi2Ints, "fmi2GetBoolean", "", |f| f(
                    h,
                    vrs.as_ptr(),
                    n,
                    ints.as_mut_ptr()
                ))?;
                for (b, i) in values.iter_mut().zip(ints) {
                    *b = i != 0;
                }
                Ok(())
            }
            FmiVersion::V3 => call!(self, Fmi3GetBool, "", "fmi3GetBoolean", |f| f(
                h,
                vrs.as_ptr(),
                n,
                values.as_mut_ptr(),
                n
            )),
        }
    }

    pub fn enter_event_mode(&mut self) -> Result<(), FmuError> {
        let h = self.handle;
        call!(
            self,
            Fmi2Status0,
            "fmi2EnterEventMode",
            "fmi3EnterEventMode",
            |f| f(h)
        )
    }

    pub fn enter_continuous_time_mode(&mut self) -> Result<(), FmuError> {
        let h = self.handle;
        call!(
            self,
            Fmi2Status0,
            "fmi2EnterContinuousTimeMode",
            "fmi3EnterContinuousTimeMode",
            |f| f(h)
        )
    }

    /// One pass of the event iteration.
    pub fn update_discrete_states(&mut self) -> Result<EventUpdate, FmuError> {
        let h = self.handle;
        match self.lib.version {
            FmiVersion::V2 => {
                let mut info = Fmi2EventInfo::default();
                let p = &mut info as *mut Fmi2EventInfo;
                call!(
                    self,
                    Fmi2NewDiscreteStates,
                    "fmi2NewDiscreteStates",
                    "",
                    |f| f(h, p)
                )?;
                Ok(EventUpdate {
                    again: info.new_discrete_states_needed != 0,
                    terminate: info.terminate_simulation != 0,
                    values_changed: info.values_changed != 0,
                    next_event_time: (info.next_event_time_defined != 0)
                        .then_some(info.next_event_time),
                })
            }
            FmiVersion::V3 => {
                let (mut again, mut terminate, mut nominals, mut values, mut defined) =
                    (false, false, false, false, false);
                let mut next = 0.0;
                call!(
                    self,
                    Fmi3UpdateDiscrete,
                    "",
                    "fmi3UpdateDiscreteStates",
                    |f| f(
                        h,
                        &mut again,
                        &mut terminate,
                        &mut nominals,
                        &mut values,
                        &mut defined,
                        &mut next
                    )
                )?;
                Ok(EventUpdate {
                    again,
                    terminate,
                    values_changed: values,
                    next_event_time: defined.then_some(next),
                })
            }
        }
    }

    pub fn set_time(&mut self, t: f64) -> Result<(), FmuError> {
        let h = self.handle;
        call!(self, Fmi2SetTime, "fmi2SetTime", "fmi3SetTime", |f| f(h, t))
    }

    pub fn set_states(&mut self, x: &[f64]) -> Result<(), FmuError> {
        let h = self.handle;
        call!(
            self,
            Fmi2SetArray,
            "fmi2SetContinuousStates",
            "fmi3SetContinuousStates",
            |f| f(h, x.as_ptr(), x.len())
        )
    }

    pub fn get_states(&mut self, x: &mut [f64]) -> Result<(), FmuError> {
        let h = self.handle;
        call!(
            self,
            Fmi2Array,
            "fmi2GetContinuousStates",
            "fmi3GetContinuousStates",
            |f| f(h, x.as_mut_ptr(), x.len())
        )
    }

    pub fn get_derivatives(&mut self, dx: &mut [f64]) -> Result<(), FmuError> {
        let h = self.handle;
        call!(
            self,
            Fmi2Array,
            "fmi2GetDerivatives",
            "fmi3GetContinuousStateDerivatives",
            |f| f(h, dx.as_mut_ptr(), dx.len())
        )
    }

    pub fn get_event_indicators(&mut self, z: &mut [f64]) -> Result<(), FmuError> {
        let h = self.handle;
        call!(
            self,
            Fmi2Array,
            "fmi2GetEventIndicators",
            "fmi3GetEventIndicators",
            |f| f(h, z.as_mut_ptr(), z.len())
        )
    }

    /// Whether the library has `fmi*CompletedIntegratorStep` (every Model Exchange FMU
    /// should; one that lacks it is taken not to need it).
    pub fn has_completed_integrator_step(&self) -> bool {
        let slot = match self.lib.version {
            FmiVersion::V2 => const { slot("fmi2CompletedIntegratorStep") },
            FmiVersion::V3 => const { slot("fmi3CompletedIntegratorStep") },
        };
        self.lib.functions[slot] != 0
    }

    /// A Model Exchange instance's integrator step is complete at the time and states set
    /// last (no state before them will be set again): `(enter event mode, terminate)`.
    pub fn completed_integrator_step(&mut self) -> Result<(bool, bool), FmuError> {
        let h = self.handle;
        match self.lib.version {
            FmiVersion::V2 => {
                let (mut event, mut terminate): (c_int, c_int) = (0, 0);
                call!(
                    self,
                    Fmi2CompletedStep,
                    "fmi2CompletedIntegratorStep",
                    "",
                    |f| f(h, 1, &mut event, &mut terminate)
                )?;
                Ok((event != 0, terminate != 0))
            }
            FmiVersion::V3 => {
                let (mut event, mut terminate) = (false, false);
                call!(
                    self,
                    Fmi3CompletedStep,
                    "",
                    "fmi3CompletedIntegratorStep",
                    |f| f(h, true, &mut event, &mut terminate)
                )?;
                Ok((event, terminate))
            }
        }
    }

    /// Advance a Co-Simulation instance from `t` by `dt`; `true` when the FMU asks to stop.
    pub fn do_step(&mut self, t: f64, dt: f64) -> Result<bool, FmuError> {
        let h = self.handle;
        match self.lib.version {
            FmiVersion::V2 => {
                let step: Fmi2DoStep = sym!(self.lib, "fmi2DoStep")?;
                // SAFETY: a live instance and arguments as the standard declares them.
                let status = unsafe { step(h, t, dt, 1) };
                if status == 2 {
                    // Discard: the FMU may have stopped because it asked to terminate.
                    let get: Fmi2BooleanStatus = sym!(self.lib, "fmi2GetBooleanStatus")?;
                    let mut terminated: c_int = 0;
                    // SAFETY: as above; 3 is fmi2Terminated.
                    let asked = unsafe { get(h, 3, &mut terminated) };
                    if asked == 0 && terminated != 0 {
                        return Ok(true);
                    }
                }
                self.check("fmi2DoStep", status)?;
                Ok(false)
            }
            FmiVersion::V3 => {
                let (mut event, mut terminate, mut early) = (false, false, false);
                let mut last = 0.0;
                call!(self, Fmi3DoStep, "", "fmi3DoStep", |f| f(
                    h,
                    t,
                    dt,
                    true,
                    &mut event,
                    &mut terminate,
                    &mut early,
                    &mut last
                ))?;
                Ok(terminate)
            }
        }
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        if self.handle.is_null() {
            return;
        }
        let free: Result<Fmi2FreeInstance, _> = match self.lib.version {
            FmiVersion::V2 => sym!(self.lib, "fmi2FreeInstance"),
            FmiVersion::V3 => sym!(self.lib, "fmi3FreeInstance"),
        };
        if let Ok(free) = free {
            // SAFETY: the instance is live and freed once.
            unsafe { free(self.handle) }
        }
    }
}

// SAFETY: an instance is used by one thread at a time (it moves between the threads of a
// pool, which FMI allows); its log sink is behind a mutex.
unsafe impl Send for Instance {}
