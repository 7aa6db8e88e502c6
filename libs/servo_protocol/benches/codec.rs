//! Encode/decode timing. `cargo bench -p servo_protocol`.
use criterion::{criterion_group, criterion_main, Criterion};
use servo_protocol::{decode, encode, Frame, Message};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let f = Frame {
        seq: 9,
        msg: Message::SetPulses {
            ticks: [2944, 3100, 2700, 1500],
        },
    };
    c.bench_function("encode_set_pulses", |b| {
        b.iter(|| black_box(encode(black_box(&f))))
    });
    let bytes = encode(&f);
    c.bench_function("decode_set_pulses", |b| {
        b.iter(|| {
            let mut buf = bytes.clone();
            black_box(decode(&mut buf))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
