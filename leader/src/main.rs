//! `formation-leader`: the leader process (publishes the reference frame). Filled in by the runtime.
fn main() {
    eprintln!("formation-leader: run it through `formation run`");
    std::process::exit(2);
}
