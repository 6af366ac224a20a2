//! The FMI 2.0 and 3.0 C functions calib calls and the structures they take, as the
//! standard's headers declare them (`fmi2FunctionTypes.h`, `fmi3FunctionTypes.h`).

#![allow(non_snake_case, non_camel_case_types)]

use std::ffi::{c_char, c_double, c_int, c_uint, c_void};

pub(super) type Ptr = *mut c_void;

// FMI 2.0
pub(super) type Fmi2Instantiate = unsafe extern "C" fn(
    *const c_char,
    c_int,
    *const c_char,
    *const c_char,
    *const Fmi2Callbacks,
    c_int,
    c_int,
) -> Ptr;
pub(super) type Fmi2Logger =
    unsafe extern "C" fn(Ptr, *const c_char, c_int, *const c_char, *const c_char, ...);
pub(super) type Fmi2Status0 = unsafe extern "C" fn(Ptr) -> c_int;
pub(super) type Fmi2FreeInstance = unsafe extern "C" fn(Ptr);
pub(super) type Fmi2SetupExperiment =
    unsafe extern "C" fn(Ptr, c_int, c_double, c_double, c_int, c_double) -> c_int;
pub(super) type Fmi2Reals = unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut c_double) -> c_int;
pub(super) type Fmi2SetReals =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *const c_double) -> c_int;
pub(super) type Fmi2Ints = unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut c_int) -> c_int;
pub(super) type Fmi3GetI32 =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut i32, usize) -> c_int;
pub(super) type Fmi3GetBool =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut bool, usize) -> c_int;
pub(super) type Fmi2SetInts =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *const c_int) -> c_int;
pub(super) type Fmi3SetI32 =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *const i32, usize) -> c_int;
pub(super) type Fmi3SetBool =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *const bool, usize) -> c_int;
pub(super) type Fmi2NewDiscreteStates = unsafe extern "C" fn(Ptr, *mut Fmi2EventInfo) -> c_int;
pub(super) type Fmi2SetTime = unsafe extern "C" fn(Ptr, c_double) -> c_int;
pub(super) type Fmi2Array = unsafe extern "C" fn(Ptr, *mut c_double, usize) -> c_int;
pub(super) type Fmi2SetArray = unsafe extern "C" fn(Ptr, *const c_double, usize) -> c_int;
pub(super) type Fmi2BooleanStatus = unsafe extern "C" fn(Ptr, c_int, *mut c_int) -> c_int;
pub(super) type Fmi2DoStep = unsafe extern "C" fn(Ptr, c_double, c_double, c_int) -> c_int;
pub(super) type Fmi2CompletedStep =
    unsafe extern "C" fn(Ptr, c_int, *mut c_int, *mut c_int) -> c_int;
pub(super) type Fmi3CompletedStep = unsafe extern "C" fn(Ptr, bool, *mut bool, *mut bool) -> c_int;

#[repr(C)]
pub(super) struct Fmi2Callbacks {
    pub(super) logger: Fmi2Logger,
    pub(super) allocate: unsafe extern "C" fn(usize, usize) -> *mut c_void,
    pub(super) free: unsafe extern "C" fn(*mut c_void),
    pub(super) step_finished: Option<unsafe extern "C" fn(Ptr, c_int)>,
    pub(super) environment: Ptr,
}

#[repr(C)]
#[derive(Default)]
pub(super) struct Fmi2EventInfo {
    pub(super) new_discrete_states_needed: c_int,
    pub(super) terminate_simulation: c_int,
    pub(super) nominals_changed: c_int,
    pub(super) values_changed: c_int,
    pub(super) next_event_time_defined: c_int,
    pub(super) next_event_time: c_double,
}

// FMI 3.0
pub(super) type Fmi3Logger = unsafe extern "C" fn(Ptr, c_int, *const c_char, *const c_char);
pub(super) type Fmi3InstantiateME = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    Ptr,
    Option<Fmi3Logger>,
) -> Ptr;
pub(super) type Fmi3InstantiateCS = unsafe extern "C" fn(
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
pub(super) type Fmi3EnterInit =
    unsafe extern "C" fn(Ptr, bool, c_double, c_double, bool, c_double) -> c_int;
pub(super) type Fmi3GetF64 =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *mut c_double, usize) -> c_int;
pub(super) type Fmi3SetF64 =
    unsafe extern "C" fn(Ptr, *const c_uint, usize, *const c_double, usize) -> c_int;
pub(super) type Fmi3UpdateDiscrete = unsafe extern "C" fn(
    Ptr,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut c_double,
) -> c_int;
pub(super) type Fmi3DoStep = unsafe extern "C" fn(
    Ptr,
    c_double,
    c_double,
    bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut c_double,
) -> c_int;
