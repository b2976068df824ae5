//! Print what `hitl_record::reader` finds in a recording: counts per topic and how it ends.

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: read_recording FILE.mcap");
        std::process::exit(2);
    };
    match hitl_record::reader::read_recording(std::path::Path::new(&path)) {
        Ok(r) => {
            println!("{:?}", r.topic_counts);
            println!("{:?}", r.end);
        }
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    }
}
