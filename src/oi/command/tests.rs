//! Unit tests of command encoding and parsing: every opcode's bytes, argument checks, per-model lengths.
use super::*;
use crate::oi::packets::available_on;
use proptest::prelude::*;

const MODELS: [Model; 2] = [Model::Create1, Model::Create2];

#[test]
fn drive_spec_example_and_special_radii() {
    let drive = |velocity, radius| Command::Drive { velocity, radius }.encode(Model::Create2);
    // v = -200, r = 500 -> [137][255][56][1][244] [C1 p9; C2 p13]
    for model in MODELS {
        let c = Command::Drive {
            velocity: -200,
            radius: Radius::Mm(500),
        };
        assert_eq!(c.encode(model).unwrap(), vec![137, 255, 56, 1, 244]);
    }
    assert_eq!(
        drive(0, Radius::Straight).unwrap(),
        vec![137, 0, 0, 0x80, 0x00]
    );
    assert_eq!(
        drive(100, Radius::TurnInPlaceClockwise).unwrap(),
        vec![137, 0, 100, 0xFF, 0xFF]
    );
    assert_eq!(
        drive(100, Radius::TurnInPlaceCounterClockwise).unwrap(),
        vec![137, 0, 100, 0, 1]
    );
    assert!(drive(501, Radius::Straight).is_err());
    assert!(drive(-501, Radius::Straight).is_err());
    assert!(drive(100, Radius::Mm(2001)).is_err());
    assert!(drive(100, Radius::Mm(0)).is_err());
    assert!(drive(500, Radius::Mm(-2000)).is_ok());
    assert_eq!(Radius::from_wire(0x7FFF), Radius::Straight);
}

#[test]
fn drive_direct_sends_the_right_wheel_first() {
    let c = Command::DriveDirect {
        right: 100,
        left: -100,
    };
    assert_eq!(
        c.encode(Model::Create1).unwrap(),
        vec![145, 0, 100, 0xFF, 0x9C]
    );
    let c = Command::DrivePwm {
        right: -255,
        left: 1,
    };
    assert_eq!(
        c.encode(Model::Create2).unwrap(),
        vec![146, 0xFF, 0x01, 0, 1]
    );
    assert!(
        Command::DriveDirect {
            right: 0,
            left: 501
        }
        .encode(Model::Create2)
        .is_err()
    );
}

#[test]
fn model_only_commands_are_refused_on_the_other_model() {
    for c in [Command::Stop, Command::Reset, Command::Power, Command::Max] {
        assert_eq!(
            c.encode(Model::Create1),
            Err(OiError::CommandNotOnModel {
                command: c.name(),
                model: Model::Create1
            })
        );
        assert!(c.encode(Model::Create2).is_ok());
    }
    assert_eq!(Command::Stop.encode(Model::Create2).unwrap(), vec![173]);
    assert_eq!(Command::Reset.encode(Model::Create2).unwrap(), vec![7]);
    assert_eq!(Command::Max.encode(Model::Create2).unwrap(), vec![136]);
    assert_eq!(
        Command::Demo(-1).encode(Model::Create1).unwrap(),
        vec![136, 255]
    );
    assert!(Command::Demo(0).encode(Model::Create2).is_err());
    assert!(Command::Demo(10).encode(Model::Create1).is_err());
    assert!(
        Command::DrivePwm { right: 0, left: 0 }
            .encode(Model::Create1)
            .is_err()
    );
}

#[test]
fn stream_lists_are_checked_per_model() {
    let stream = |ids: &[u8], m| Command::Stream(ids.to_vec()).encode(m);
    assert_eq!(
        stream(&[29, 13], Model::Create2).unwrap(),
        vec![148, 2, 29, 13]
    );
    assert_eq!(stream(&[6], Model::Create1).unwrap(), vec![148, 1, 6]);
    assert_eq!(stream(&[], Model::Create1), Err(OiError::EmptyStreamList));
    assert_eq!(
        stream(&[100], Model::Create1),
        Err(OiError::NotOnModel {
            id: 100,
            model: Model::Create1
        })
    );
    assert_eq!(
        stream(&[7, 102], Model::Create2),
        Err(OiError::UnknownPacket(102))
    );
    assert_eq!(
        stream(&[7; 44], Model::Create1),
        Err(OiError::TooManyPackets {
            count: 44,
            limit: 43,
            model: Model::Create1
        })
    );
    assert!(stream(&[7; 43], Model::Create1).is_ok());
    assert_eq!(
        Command::QueryList(vec![]).encode(Model::Create2),
        Err(OiError::EmptyStreamList)
    );
    assert!(Command::Sensors(43).encode(Model::Create1).is_err());
    assert_eq!(
        Command::Sensors(100).encode(Model::Create2).unwrap(),
        vec![142, 100]
    );
    assert_eq!(
        Command::PauseStream.encode(Model::Create1).unwrap(),
        vec![150, 0]
    );
    assert_eq!(
        Command::ResumeStream.encode(Model::Create1).unwrap(),
        vec![150, 1]
    );
}

#[test]
fn argument_ranges_are_checked_per_model() {
    let song = |number, n| Command::Song {
        number,
        notes: vec![(60, 32); n],
    };
    assert!(song(15, 16).encode(Model::Create1).is_ok());
    assert!(song(5, 1).encode(Model::Create2).is_err());
    assert!(song(0, 17).encode(Model::Create1).is_err());
    assert!(song(0, 0).encode(Model::Create1).is_err());
    assert!(Command::Play(4).encode(Model::Create2).is_ok());
    assert!(Command::Play(5).encode(Model::Create2).is_err());
    assert!(Command::Baud(11).encode(Model::Create1).is_ok());
    assert!(Command::Baud(12).encode(Model::Create1).is_err());
    assert!(Command::Motors(0x1F).encode(Model::Create2).is_ok());
    assert!(Command::Motors(0x08).encode(Model::Create1).is_err());
    let leds = |bits| Command::Leds {
        bits,
        power_color: 255,
        power_intensity: 128,
    };
    assert_eq!(
        leds(10).encode(Model::Create1).unwrap(),
        vec![139, 10, 255, 128]
    );
    assert!(leds(1).encode(Model::Create1).is_err());
    assert!(leds(0x0F).encode(Model::Create2).is_ok());
    assert!(
        Command::PwmMotors([128, 128, 128])
            .encode(Model::Create1)
            .is_ok()
    );
    assert!(
        Command::PwmMotors([129, 0, 0])
            .encode(Model::Create1)
            .is_err()
    );
    assert!(
        Command::PwmMotors([0x81, 127, 127])
            .encode(Model::Create2)
            .is_ok()
    );
    assert!(
        Command::PwmMotors([0x80, 0, 0])
            .encode(Model::Create2)
            .is_err()
    );
    assert!(
        Command::PwmMotors([0, 0, 128])
            .encode(Model::Create2)
            .is_err()
    );
    let other = |opcode, data: &[u8]| Command::Other {
        opcode,
        data: data.to_vec(),
    };
    assert!(other(147, &[7]).encode(Model::Create1).is_ok());
    assert!(
        other(147, &[7]).encode(Model::Create2).is_err(),
        "removed on the Create 2"
    );
    assert!(
        other(137, &[0, 0, 0, 0]).encode(Model::Create1).is_err(),
        "Drive has a variant"
    );
    assert!(
        other(164, &[65, 66, 67]).encode(Model::Create2).is_err(),
        "needs 4 bytes"
    );
    assert!(
        other(152, &[3, 137, 0]).encode(Model::Create1).is_err(),
        "count mismatch"
    );
    assert!(other(152, &[0]).encode(Model::Create1).is_ok());
}

#[test]
fn parse_knows_the_per_model_lengths() {
    assert_eq!(
        parse_command(Model::Create1, &[136]),
        ParsedCommand::Incomplete,
        "Demo has a data byte on the Create 1"
    );
    assert_eq!(
        parse_command(Model::Create2, &[136, 128]),
        ParsedCommand::Complete {
            command: Command::Max,
            consumed: 1
        }
    );
    assert_eq!(
        parse_command(Model::Create1, &[173]),
        ParsedCommand::UnknownOpcode(173)
    );
    assert_eq!(
        parse_command(Model::Create1, &[7]),
        ParsedCommand::UnknownOpcode(7)
    );
    assert_eq!(
        parse_command(Model::Create2, &[147, 1]),
        ParsedCommand::UnknownOpcode(147)
    );
    assert_eq!(
        parse_command(Model::Create2, &[0]),
        ParsedCommand::UnknownOpcode(0)
    );
    assert_eq!(
        parse_command(Model::Create2, &[]),
        ParsedCommand::Incomplete
    );
    assert_eq!(
        parse_command(Model::Create2, &[150, 7]),
        ParsedCommand::Complete {
            command: Command::Other {
                opcode: 150,
                data: vec![7]
            },
            consumed: 2
        }
    );
    // Song with N = 2: 3 + 4 bytes.
    let song = [140, 1, 2, 60, 32, 62, 16];
    for cut in 0..song.len() {
        assert_eq!(
            parse_command(Model::Create1, &song[..cut]),
            ParsedCommand::Incomplete
        );
    }
    assert_eq!(
        parse_command(Model::Create1, &song),
        ParsedCommand::Complete {
            command: Command::Song {
                number: 1,
                notes: vec![(60, 32), (62, 16)]
            },
            consumed: 7
        }
    );
}

fn radius() -> impl Strategy<Value = Radius> {
    prop_oneof![
        Just(Radius::Straight),
        Just(Radius::TurnInPlaceClockwise),
        Just(Radius::TurnInPlaceCounterClockwise),
        (-2000i16..=2000)
            .prop_filter("0 and ±1 are special", |r| r.abs() > 1)
            .prop_map(Radius::Mm),
    ]
}

fn packet_id(model: Model) -> impl Strategy<Value = u8> + Clone {
    let ids: Vec<u8> = (0..=255).filter(|&id| available_on(id, model)).collect();
    prop::sample::select(ids)
}

fn other(model: Model) -> impl Strategy<Value = Command> {
    let fixed: Vec<(u8, usize)> = match model {
        Model::Create1 => vec![
            (147, 1),
            (151, 1),
            (153, 0),
            (154, 0),
            (155, 1),
            (156, 2),
            (157, 2),
            (158, 1),
        ],
        Model::Create2 => vec![(162, 2), (163, 4), (164, 4), (165, 1), (167, 15), (168, 3)],
    };
    let fixed = prop::sample::select(fixed).prop_flat_map(|(opcode, n)| {
        prop::collection::vec(any::<u8>(), n).prop_map(move |data| Command::Other { opcode, data })
    });
    let script = prop::collection::vec(any::<u8>(), 0..=100).prop_map(|body| {
        let mut data = vec![body.len() as u8];
        data.extend(body);
        Command::Other { opcode: 152, data }
    });
    match model {
        Model::Create1 => prop_oneof![fixed, script].boxed(),
        Model::Create2 => fixed.boxed(),
    }
}

/// Any command that is valid on `model`.
fn command(model: Model) -> impl Strategy<Value = Command> {
    let last_song = last_song_number(model);
    let list = prop::collection::vec(packet_id(model), 1..=max_packet_list_len(model));
    let common = prop_oneof![
        prop::sample::select(vec![
            Command::Start,
            Command::Control,
            Command::Safe,
            Command::Full,
            Command::Spot,
            Command::Clean,
            Command::SeekDock,
            Command::PauseStream,
            Command::ResumeStream,
        ]),
        (0u8..=11).prop_map(Command::Baud),
        (-500i16..=500, radius())
            .prop_map(|(velocity, radius)| Command::Drive { velocity, radius }),
        (-500i16..=500, -500i16..=500)
            .prop_map(|(right, left)| Command::DriveDirect { right, left }),
        any::<u8>()
            .prop_map(move |b| Command::Motors(b & if model == Model::Create1 { 7 } else { 31 })),
        (any::<u8>(), any::<u8>(), any::<u8>()).prop_map(
            move |(b, power_color, power_intensity)| {
                let bits = b & if model == Model::Create1 { 10 } else { 15 };
                Command::Leds {
                    bits,
                    power_color,
                    power_intensity,
                }
            }
        ),
        (
            0..=last_song,
            prop::collection::vec(any::<(u8, u8)>(), 1..=16)
        )
            .prop_map(|(number, notes)| Command::Song { number, notes }),
        (0..=last_song).prop_map(Command::Play),
        packet_id(model).prop_map(Command::Sensors),
        list.clone().prop_map(Command::Stream),
        list.prop_map(Command::QueryList),
    ];
    let specific = match model {
        Model::Create1 => prop_oneof![
            (-1i8..=9).prop_map(Command::Demo),
            [0u8..=128, 0u8..=128, 0u8..=128].prop_map(Command::PwmMotors),
            other(model),
        ]
        .boxed(),
        Model::Create2 => prop_oneof![
            prop::sample::select(vec![
                Command::Reset,
                Command::Power,
                Command::Max,
                Command::Stop
            ]),
            (-255i16..=255, -255i16..=255)
                .prop_map(|(right, left)| Command::DrivePwm { right, left }),
            (-127i8..=127, -127i8..=127, 0u8..=127)
                .prop_map(|(m, s, v)| Command::PwmMotors([m as u8, s as u8, v])),
            other(model),
        ]
        .boxed(),
    };
    prop_oneof![3 => common, 1 => specific]
}

fn model_and_command() -> impl Strategy<Value = (Model, Command)> {
    prop_oneof![
        command(Model::Create1).prop_map(|c| (Model::Create1, c)),
        command(Model::Create2).prop_map(|c| (Model::Create2, c)),
    ]
}

proptest! {
    #[test]
    fn parse_round_trips_encode((model, cmd) in model_and_command(), trailing in prop::collection::vec(any::<u8>(), 0..4)) {
        let bytes = cmd.encode(model).unwrap();
        prop_assert_eq!(bytes[0], cmd.opcode(model));
        for cut in 0..bytes.len() {
            prop_assert_eq!(parse_command(model, &bytes[..cut]), ParsedCommand::Incomplete);
        }
        let mut buf = bytes.clone();
        buf.extend(&trailing);
        prop_assert_eq!(
            parse_command(model, &buf),
            ParsedCommand::Complete { command: cmd, consumed: bytes.len() }
        );
    }

    #[test]
    fn parse_never_panics_and_stays_in_bounds(model in prop::sample::select(MODELS.to_vec()),
                                              buf in prop::collection::vec(any::<u8>(), 0..40)) {
        match parse_command(model, &buf) {
            ParsedCommand::Complete { consumed, .. } => prop_assert!(consumed >= 1 && consumed <= buf.len()),
            ParsedCommand::UnknownOpcode(op) => prop_assert_eq!(Some(&op), buf.first()),
            ParsedCommand::Incomplete => {}
        }
    }
}
