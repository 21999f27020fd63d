//! The `host-sim` command (being written: issue 3).
fn main() {
    eprintln!("host-sim: the command line is not implemented yet");
    std::process::exit(2);
}
