use bite_core::msg::Kind;
use bite_sim::probe::{ProbeSpec, mission_text, probe};
use std::time::Duration;
fn main() {
    let reg = bite_protocols::registry();
    let args: Vec<String> = std::env::args().collect();
    let p = &args[1];
    let n: usize = args[2].parse().unwrap();
    let kind = if p.starts_with("sync") {
        Kind::Sync
    } else if p.starts_with("alloc") {
        Kind::Allocate
    } else {
        Kind::Terminate
    };
    let mut s = ProbeSpec::new(kind, p, n);
    s.utilities = args.get(3).is_some_and(|x| x == "u");
    if let Some(c) = args.get(4).filter(|c| !c.is_empty()) {
        let v: Vec<f64> = c.split(',').map(|x| x.parse().unwrap()).collect();
        s.crash = Some((v[0] as usize, Duration::from_secs_f64(v[1])));
    }
    if let Some(i) = args.get(5) {
        s.items = i.parse().unwrap();
    }
    let (g, sc) = mission_text(&s);
    std::fs::write("/tmp/probe.yaml", g).unwrap();
    std::fs::write("/tmp/probe-sc.yaml", sc).unwrap();
    let r = probe(&s, &reg).unwrap();
    println!("{r:#?}");
}
