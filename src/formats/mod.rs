pub mod graph;
pub mod log;
pub mod xyz;
