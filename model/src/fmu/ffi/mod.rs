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
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::path::Path;
use std::sync::{Arc, Mutex};

mod signatures;

use signatures::*;

/// Messages an instance keeps (the last ones; earlier are dropped).
const LOG_KEPT: usize = 20;

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

// After `sym!`: the instance's functions are resolved with it.
mod instance;

pub use instance::{EventUpdate, Instance};

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
        let (handle, callbacks) = match self.version {
            FmiVersion::V2 => {
                let (handle, callbacks) = self.instantiate_fmi2(&name, environment)?;
                (handle, Some(callbacks))
            }
            FmiVersion::V3 => (self.instantiate_fmi3(&name, environment)?, None),
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

    /// FMI 2.0's `fmi2Instantiate` of the instance `name`, its messages to the sink at
    /// `environment`: the handle (null on failure), and the callbacks, which must outlive it.
    fn instantiate_fmi2(
        &self,
        name: &CStr,
        environment: Ptr,
    ) -> Result<(Ptr, Box<Fmi2Callbacks>), FmuError> {
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
        Ok((h, cb))
    }

    /// FMI 3.0's `fmi3Instantiate*` of this interface for the instance `name`, its messages to
    /// the sink at `environment`: the handle (null on failure).
    fn instantiate_fmi3(&self, name: &CStr, environment: Ptr) -> Result<Ptr, FmuError> {
        Ok(match self.interface {
            Interface::ModelExchange => {
                let instantiate: Fmi3InstantiateME = sym!(self, "fmi3InstantiateModelExchange")?;
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
        })
    }
}
