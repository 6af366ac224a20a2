pub mod measurement;
