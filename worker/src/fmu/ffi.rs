//! The FMU's shared library: the FMI 2.0 and 3.0 C functions calib calls, loaded with
//! `libloading` and declared here from the standard's headers (`fmi2FunctionTypes.h`,
//! `fmi3FunctionTypes.h`), and one instance with the FMU's log messages kept.
//!
//! FMI 2.0's logger is variadic and printf-style: the function given to the FMU is a C one
//! (`csrc/fmi2_logger.c`, built by the worker's build script) that formats the message with
//! `vsnprintf` and passes the text on; value-reference escapes (`#r123#`) are kept as they
//! are. FMI 3.0's logger receives the message already formatted.

#![allow(non_snake_case, non_camel_case_types)]

use super::description::{FmiVersion, Interface};
use super::FmuError;
use std::ffi::{c_char, c_double, c_int, c_uint, c_void, CStr, CString};
use std::path::Path;
use std::sync::{Arc, Mutex};

/// Messages an instance keeps (the last ones; earlier are dropped).
const LOG_KEPT: usize = 20;

type Ptr = *mut c_void;

// FMI 2.0
type Fmi2Instantiate = unsafe extern "C" fn(
    *const c_char,
    c_int,
    *const c_char,
    *const c_char,
    *const Fmi2Callbacks,
    c_int,
    c_int,
) -> Ptr;
type Fmi2Logger =
    unsafe extern "C" fn(Ptr, *const c_char, c_int, *const c_char, *const c_char, ...);
type Fmi2Status0 = unsafe extern "C" fn(Ptr) -> c_int;
type Fmi2FreeInstance = unsafe extern "C" fn(Ptr);
type Fmi2SetupExperiment =
    unsafe extern "C" fn(Ptr, c_int, c_double, c_double, c_int, c_double) -> c_int;
type Fmi2Reals = unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut c_double) -> c_int;
type Fmi2SetReals = unsafe extern "C" fn(Ptr, *const c_uint, usize, *const c_double) -> c_int;
type Fmi2Ints = unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut c_int) -> c_int;
type Fmi3GetI32 = unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut i32, usize) -> c_int;
type Fmi3GetBool = unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut bool, usize) -> c_int;
type Fmi2SetInts = unsafe extern "C" fn(Ptr, *const c_uint, usize, *const c_int) -> c_int;
type Fmi3SetI32 = unsafe extern "C" fn(Ptr, *const c_uint, usize, *const i32, usize) -> c_int;
type Fmi3SetBool = unsafe extern "C" fn(Ptr, *const c_uint, usize, *const bool, usize) -> c_int;
type Fmi2NewDiscreteStates = unsafe extern "C" fn(Ptr, *mut Fmi2EventInfo) -> c_int;
type Fmi2SetTime = unsafe extern "C" fn(Ptr, c_double) -> c_int;
type Fmi2Array = unsafe extern "C" fn(Ptr, *mut c_double, usize) -> c_int;
type Fmi2SetArray = unsafe extern "C" fn(Ptr, *const c_double, usize) -> c_int;
type Fmi2BooleanStatus = unsafe extern "C" fn(Ptr, c_int, *mut c_int) -> c_int;
type Fmi2DoStep = unsafe extern "C" fn(Ptr, c_double, c_double, c_int) -> c_int;
type Fmi2CompletedStep = unsafe extern "C" fn(Ptr, c_int, *mut c_int, *mut c_int) -> c_int;
type Fmi3CompletedStep = unsafe extern "C" fn(Ptr, bool, *mut bool, *mut bool) -> c_int;

#[repr(C)]
struct Fmi2Callbacks {
    logger: Fmi2Logger,
    allocate: unsafe extern "C" fn(usize, usize) -> *mut c_void,
    free: unsafe extern "C" fn(*mut c_void),
    step_finished: Option<unsafe extern "C" fn(Ptr, c_int)>,
    environment: Ptr,
}

#[repr(C)]
#[derive(Default)]
struct Fmi2EventInfo {
    new_discrete_states_needed: c_int,
    terminate_simulation: c_int,
    nominals_changed: c_int,
    values_changed: c_int,
    next_event_time_defined: c_int,
    next_event_time: c_double,
}

// FMI 3.0
type Fmi3Logger = unsafe extern "C" fn(Ptr, c_int, *const c_char, *const c_char);
type Fmi3InstantiateME = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    Ptr,
    Option<Fmi3Logger>,
) -> Ptr;
type Fmi3InstantiateCS = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    bool,
    bool,
    *const c_uint,
    usize,
    Ptr,
    Option<Fmi3Logger>,
    Ptr,
) -> Ptr;
type Fmi3EnterInit = unsafe extern "C" fn(Ptr, bool, c_double, c_double, bool, c_double) -> c_int;
type Fmi3GetF64 = unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut c_double, usize) -> c_int;
type Fmi3SetF64 = unsafe extern "C" fn(Ptr, *const c_uint, usize, *const c_double, usize) -> c_int;
type Fmi3UpdateDiscrete = unsafe extern "C" fn(
    Ptr,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut c_double,
) -> c_int;
type Fmi3DoStep = unsafe extern "C" fn(
    Ptr,
    c_double,
    c_double,
    bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut c_double,
) -> c_int;

static ECHO: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Write every FMU message to stderr as it comes too (in a child process, so that the
/// parent has them when the child crashes).
pub fn echo_log_to_stderr() {
    ECHO.store(true, std::sync::atomic::Ordering::Relaxed);
}

extern "C" {
    /// FMI 2.0's logger (`csrc/fmi2_logger.c`): formats the message and calls the
    /// environment's [`LogSink::forward`].
    fn calib_fmi2_logger(
        environment: Ptr,
        instance: *const c_char,
        status: c_int,
        category: *const c_char,
        format: *const c_char,
        ...
    );
}

/// Where an instance's log messages go: the instance environment the FMU passes back. Its
/// head is what the C logger knows of it (`calib_log_sink`).
#[repr(C)]
struct LogSink {
    /// Where the C logger sends the formatted text: [`fmi3_logger`], FMI 3.0's own.
    forward: unsafe extern "C" fn(Ptr, c_int, *const c_char, *const c_char),
    messages: Mutex<Vec<String>>,
}

impl LogSink {
    fn push(&self, status: c_int, category: *const c_char, message: *const c_char) {
        // SAFETY: the FMU passes NUL-terminated strings (or null) valid during the call.
        let text = |p: *const c_char| {
            if p.is_null() {
                String::new()
            } else {
                unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
            }
        };
        let line = format!(
            "[{}] {}: {}",
            status_name(status),
            text(category),
            text(message)
        );
        if ECHO.load(std::sync::atomic::Ordering::Relaxed) {
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "{line}");
        }
        let mut messages = self.messages.lock().unwrap_or_else(|e| e.into_inner());
        if messages.len() == LOG_KEPT {
            messages.remove(0);
        }
        messages.push(line);
    }
}

fn status_name(status: c_int) -> &'static str {
    match status {
        0 => "ok",
        1 => "warning",
        2 => "discard",
        3 => "error",
        4 => "fatal",
        _ => "pending",
    }
}

unsafe extern "C" fn fmi3_logger(
    environment: Ptr,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    if let Some(sink) = unsafe { (environment as *const LogSink).as_ref() } {
        sink.push(status, category, message);
    }
}

unsafe extern "C" fn fmi2_calloc(n: usize, size: usize) -> *mut c_void {
    unsafe { libc_calloc(n, size) }
}

unsafe extern "C" fn fmi2_free(p: *mut c_void) {
    unsafe { libc_free(p) }
}

extern "C" {
    #[link_name = "calloc"]
    fn libc_calloc(n: usize, size: usize) -> *mut c_void;
    #[link_name = "free"]
    fn libc_free(p: *mut c_void);
}

/// The loaded shared library of one interface of an FMU.
/// Every FMI function calib calls; a library resolves them once, when it is loaded.
const FUNCTIONS: [&str; 45] = [
    "fmi2CompletedIntegratorStep",
    "fmi2DoStep",
    "fmi2EnterContinuousTimeMode",
    "fmi2EnterEventMode",
    "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode",
    "fmi2FreeInstance",
    "fmi2GetBoolean",
    "fmi2GetBooleanStatus",
    "fmi2GetContinuousStates",
    "fmi2GetDerivatives",
    "fmi2GetEventIndicators",
    "fmi2GetInteger",
    "fmi2GetReal",
    "fmi2Instantiate",
    "fmi2NewDiscreteStates",
    "fmi2Reset",
    "fmi2SetContinuousStates",
    "fmi2SetBoolean",
    "fmi2SetInteger",
    "fmi2SetReal",
    "fmi2SetTime",
    "fmi2SetupExperiment",
    "fmi3CompletedIntegratorStep",
    "fmi3DoStep",
    "fmi3EnterContinuousTimeMode",
    "fmi3EnterEventMode",
    "fmi3EnterInitializationMode",
    "fmi3ExitInitializationMode",
    "fmi3FreeInstance",
    "fmi3GetBoolean",
    "fmi3GetContinuousStateDerivatives",
    "fmi3GetContinuousStates",
    "fmi3GetEventIndicators",
    "fmi3GetFloat64",
    "fmi3GetInt32",
    "fmi3InstantiateCoSimulation",
    "fmi3InstantiateModelExchange",
    "fmi3Reset",
    "fmi3SetBoolean",
    "fmi3SetContinuousStates",
    "fmi3SetFloat64",
    "fmi3SetInt32",
    "fmi3SetTime",
    "fmi3UpdateDiscreteStates",
];

/// Index of `name` in [`FUNCTIONS`] (evaluated at compile time at every call site);
/// `usize::MAX` for "" (no such function in this FMI version).
const fn slot(name: &str) -> usize {
    let name = name.as_bytes();
    if name.is_empty() {
        return usize::MAX;
    }
    let mut i = 0;
    while i < FUNCTIONS.len() {
        let f = FUNCTIONS[i].as_bytes();
        if f.len() == name.len() {
            let mut j = 0;
            while j < f.len() && f[j] == name[j] {
                j += 1;
            }
            if j == f.len() {
                return i;
            }
        }
        i += 1;
    }
    panic!("an FMI function missing from FUNCTIONS")
}

/// The function `name` of a library, resolved when it was loaded.
macro_rules! sym {
    ($lib:expr, $name:literal) => {
        $lib.symbol(const { slot($name) }, $name)
    };
}

pub struct Library {
    version: FmiVersion,
    /// Address of each of [`FUNCTIONS`] in the library (0: absent).
    functions: [usize; FUNCTIONS.len()],
    interface: Interface,
    /// Keeps the shared library loaded while its functions may be called.
    _lib: libloading::Library,
    identifier: String,
    token: CString,
    resource_location: CString,
}

impl Library {
    /// Load `binaries/<platform>/<identifier>.so` of the FMU unpacked at `dir`.
    pub fn load(
        dir: &Path,
        version: FmiVersion,
        interface: Interface,
        identifier: &str,
        token: &str,
    ) -> Result<Self, FmuError> {
        let platform = match version {
            FmiVersion::V2 => "linux64",
            FmiVersion::V3 => "x86_64-linux",
        };
        let path = dir
            .join("binaries")
            .join(platform)
            .join(format!("{identifier}.so"));
        if !path.is_file() {
            return Err(FmuError::Binary(format!(
                "no binary for this platform: {} is missing",
                path.strip_prefix(dir).unwrap_or(&path).display()
            )));
        }
        // SAFETY: loading an FMU runs its native initialisers; calib only does so in the
        // processes that are allowed to (a child process per slot on workers).
        let lib = unsafe { libloading::Library::new(&path) }
            .map_err(|e| FmuError::Binary(format!("cannot load {}: {e}", path.display())))?;
        let resources = dir.join("resources");
        let resource_location = match version {
            // FMI 2.0: a file URI; FMI 3.0: a path with a trailing separator.
            FmiVersion::V2 => format!("file://{}", resources.display()),
            FmiVersion::V3 => format!("{}/", resources.display()),
        };
        let mut functions = [0usize; FUNCTIONS.len()];
        for (address, name) in functions.iter_mut().zip(FUNCTIONS) {
            // SAFETY: only the address is read; it is called with its standard signature.
            if let Ok(f) = unsafe { lib.get::<unsafe extern "C" fn()>(name.as_bytes()) } {
                *address = *f as usize;
            }
        }
        Ok(Self {
            version,
            functions,
            interface,
            _lib: lib,
            identifier: identifier.to_string(),
            token: CString::new(token).unwrap_or_default(),
            resource_location: CString::new(resource_location).unwrap_or_default(),
        })
    }

    /// The function at `slot` of [`FUNCTIONS`] (called `name`), as type `T`.
    fn symbol<T: Copy>(&self, slot: usize, name: &str) -> Result<T, FmuError> {
        match self.functions.get(slot) {
            Some(&address) if address != 0 => {
                assert_eq!(std::mem::size_of::<T>(), std::mem::size_of::<usize>());
                // SAFETY: `T` is the standard's signature of the function called `name`,
                // a function pointer the size of an address.
                Ok(unsafe { std::mem::transmute_copy::<usize, T>(&address) })
            }
            _ => Err(FmuError::Binary(format!(
                "{}.so lacks `{name}`",
                self.identifier
            ))),
        }
    }

    /// A new instance of the FMU.
    pub fn instantiate(self: &Arc<Self>) -> Result<Instance, FmuError> {
        let sink = Box::new(LogSink {
            forward: fmi3_logger,
            messages: Mutex::new(Vec::new()),
        });
        let environment = &*sink as *const LogSink as Ptr;
        let name = CString::new("calib").expect("no NUL");
        let mut callbacks = None;
        let handle = match self.version {
            FmiVersion::V2 => {
                let instantiate: Fmi2Instantiate = sym!(self, "fmi2Instantiate")?;
                let cb = Box::new(Fmi2Callbacks {
                    logger: calib_fmi2_logger,
                    allocate: fmi2_calloc,
                    free: fmi2_free,
                    step_finished: None,
                    environment,
                });
                let kind = match self.interface {
                    Interface::ModelExchange => 0,
                    Interface::CoSimulation => 1,
                };
                // SAFETY: arguments as fmi2Instantiate declares them; `cb` outlives the instance.
                let h = unsafe {
                    instantiate(
                        name.as_ptr(),
                        kind,
                        self.token.as_ptr(),
                        self.resource_location.as_ptr(),
                        &*cb,
                        0,
                        0,
                    )
                };
                callbacks = Some(cb);
                h
            }
            FmiVersion::V3 => match self.interface {
                Interface::ModelExchange => {
                    let instantiate: Fmi3InstantiateME =
                        sym!(self, "fmi3InstantiateModelExchange")?;
                    // SAFETY: arguments as fmi3InstantiateModelExchange declares them.
                    unsafe {
                        instantiate(
                            name.as_ptr(),
                            self.token.as_ptr(),
                            self.resource_location.as_ptr(),
                            false,
                            false,
                            environment,
                            Some(fmi3_logger),
                        )
                    }
                }
                Interface::CoSimulation => {
                    let instantiate: Fmi3InstantiateCS = sym!(self, "fmi3InstantiateCoSimulation")?;
                    // SAFETY: arguments as fmi3InstantiateCoSimulation declares them.
                    unsafe {
                        instantiate(
                            name.as_ptr(),
                            self.token.as_ptr(),
                            self.resource_location.as_ptr(),
                            false,
                            false,
                            false,
                            false,
                            std::ptr::null(),
                            0,
                            environment,
                            Some(fmi3_logger),
                            std::ptr::null_mut(),
                        )
                    }
                }
            },
        };
        let instance = Instance {
            lib: Arc::clone(self),
            handle,
            sink,
            _callbacks: callbacks,
        };
        if handle.is_null() {
            return Err(instance.failure("instantiate", 3));
        }
        Ok(instance)
    }
}

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
    lib: Arc<Library>,
    handle: Ptr,
    sink: Box<LogSink>,
    _callbacks: Option<Box<Fmi2Callbacks>>,
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

    fn failure(&self, function: &str, status: c_int) -> FmuError {
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
