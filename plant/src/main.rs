//! `formation-plant`: the plant process. Filled in by the runtime.
fn main() {
    eprintln!("formation-plant: run it through `formation run`");
    std::process::exit(2);
}
