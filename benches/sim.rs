//! Benchmarks of the simulated Create: one 15 ms `step()` of a driving robot streaming the whole
//! sensor group (group 100 on the Create 2, group 6 on the Create 1), output drained every step.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use pavlov::oi::Model;
use pavlov::sim::params::SimParams;
use pavlov::sim::robot::SimRobot;

/// A robot in Safe mode, spinning, streaming its model's all-sensors group.
fn streaming_robot(model: Model) -> SimRobot {
    let mut robot = SimRobot::new(model, SimParams::for_model(model), 1);
    robot.receive(&[128, 131]);
    // Drive Direct: right +200, left −200 mm/s (spin in place, never hits a wall).
    robot.receive(&[145, 0, 200, 255, 56]);
    robot.receive(&[148, 1, model.all_sensors_group()]);
    for _ in 0..100 {
        robot.step();
    }
    robot.take_output();
    robot
}

fn bench_step(c: &mut Criterion) {
    for model in [Model::Create2, Model::Create1] {
        let mut robot = streaming_robot(model);
        let name = format!("sim/step_streaming_group_{}", model.all_sensors_group());
        c.bench_function(&name, |b| {
            b.iter(|| {
                robot.step();
                black_box(robot.take_output())
            })
        });
    }
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
