//! The channel's frames: a 4-byte little-endian length and a body of little-endian
//! numbers; values travel as their bits, so results are those of an in-process run, bit for
//! bit.

use super::*;

pub(super) fn read_frame(r: &mut impl Read) -> std::io::Result<Vec<u8>> {
    let mut len = [0u8; 4];
    r.read_exact(&mut len)?;
    let len = u32::from_le_bytes(len) as usize;
    if len > MAX_FRAME {
        return Err(std::io::Error::other("frame too long"));
    }
    let mut body = vec![0u8; len];
    r.read_exact(&mut body)?;
    Ok(body)
}

pub(super) fn write_frame(w: &mut impl Write, body: &[u8]) -> std::io::Result<()> {
    let mut frame = Vec::with_capacity(4 + body.len());
    frame.extend_from_slice(&(body.len() as u32).to_le_bytes());
    frame.extend_from_slice(body);
    w.write_all(&frame)?;
    w.flush()
}

#[derive(Default)]
pub(super) struct Writer(Vec<u8>);

impl Writer {
    pub(super) fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub(super) fn f64(&mut self, v: f64) -> &mut Self {
        self.u64(v.to_bits())
    }
    pub(super) fn f64s(&mut self, v: &[f64]) -> &mut Self {
        self.u64(v.len() as u64);
        for x in v {
            self.f64(*x);
        }
        self
    }
    pub(super) fn text(&mut self, s: &str) -> &mut Self {
        self.u64(s.len() as u64);
        self.0.extend_from_slice(s.as_bytes());
        self
    }
}

pub(super) struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    pub(super) fn u64(&mut self) -> Option<u64> {
        let (head, rest) = self.0.split_at_checked(8)?;
        self.0 = rest;
        Some(u64::from_le_bytes(head.try_into().ok()?))
    }
    pub(super) fn f64(&mut self) -> Option<f64> {
        self.u64().map(f64::from_bits)
    }
    pub(super) fn len(&mut self) -> Option<usize> {
        let n = usize::try_from(self.u64()?).ok()?;
        (n <= self.0.len()).then_some(n)
    }
    pub(super) fn f64s(&mut self) -> Option<Vec<f64>> {
        let n = self.len()?;
        (0..n).map(|_| self.f64()).collect()
    }
    pub(super) fn text(&mut self) -> Option<String> {
        let n = self.len()?;
        let (head, rest) = self.0.split_at_checked(n)?;
        self.0 = rest;
        Some(String::from_utf8_lossy(head).into_owned())
    }
}

pub(super) fn encode_request(
    params: &[f64],
    grid: &[f64],
    outputs: &[usize],
    options: &SolverOptions,
    inputs: &Inputs,
) -> Vec<u8> {
    let mut w = Writer::default();
    w.f64s(params).f64s(grid).u64(outputs.len() as u64);
    for o in outputs {
        w.u64(*o as u64);
    }
    w.f64(options.rtol)
        .f64(options.atol)
        .u64(options.max_steps as u64)
        .f64(options.start_time)
        .f64(options.communication_step.unwrap_or(0.0));
    // The signals, once per simulation: the child samples them at every step itself.
    w.u64(inputs.signals.len() as u64);
    for s in &inputs.signals {
        w.u64(s.input as u64)
            .u64(u64::from(s.interpolation.code()))
            .f64s(&s.times)
            .f64s(&s.values);
    }
    w.0
}

type Request = (Vec<f64>, Vec<f64>, Vec<usize>, SolverOptions, Inputs);

pub(super) fn decode_request(frame: &[u8]) -> Option<Request> {
    let mut r = Reader(frame);
    let params = r.f64s()?;
    let grid = r.f64s()?;
    let n = r.len()?;
    let outputs = (0..n)
        .map(|_| r.u64().map(|o| o as usize))
        .collect::<Option<Vec<_>>>()?;
    let options = SolverOptions {
        rtol: r.f64()?,
        atol: r.f64()?,
        max_steps: r.u64()? as usize,
        start_time: r.f64()?,
        // 0: none (a communication step is positive).
        communication_step: Some(r.f64()?).filter(|h| *h != 0.0),
    };
    let n = r.len()?;
    let signals = (0..n)
        .map(|_| {
            Some(InputSignal {
                input: usize::try_from(r.u64()?).ok()?,
                interpolation: match r.u64()? {
                    0 => Interpolation::Linear,
                    1 => Interpolation::Hold,
                    _ => return None,
                },
                times: r.f64s()?.into(),
                values: r.f64s()?.into(),
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some((params, grid, outputs, options, Inputs { signals }))
}

pub(super) fn encode_reply(result: &Result<Trajectory, SimulationError>) -> Vec<u8> {
    let mut w = Writer::default();
    match result {
        Ok(t) => {
            w.u64(0);
            let s = t.stats;
            for v in [
                s.accepted_steps,
                s.rejected_steps,
                s.rhs_evaluations,
                s.events,
            ] {
                w.u64(v as u64);
            }
            w.u64(t.values.len() as u64);
            for series in &t.values {
                w.f64s(series);
            }
        }
        Err(e) => {
            let (kind, time, count, span, text) = match e {
                SimulationError::StepLimit { limit, time } => (1, *time, *limit, 0.0, ""),
                SimulationError::StepTooSmall { time } => (2, *time, 0, 0.0, ""),
                SimulationError::Chattering {
                    time,
                    event,
                    events,
                    span,
                } => (3, *time, *events, *span, event.as_str()),
                SimulationError::Diverged { time } => (4, *time, 0, 0.0, ""),
                SimulationError::InvalidInput(m) => (5, 0.0, 0, 0.0, m.as_str()),
                SimulationError::Failed { time, reason } => (6, *time, 0, 0.0, reason.as_str()),
            };
            w.u64(kind).f64(time).u64(count as u64).f64(span).text(text);
        }
    }
    w.0
}

pub(super) fn decode_reply(
    frame: &[u8],
    grid: &[f64],
) -> Result<Result<Trajectory, SimulationError>, FmuError> {
    let malformed = || FmuError::Host("malformed reply from the FMU host".into());
    let mut r = Reader(frame);
    let kind = r.u64().ok_or_else(malformed)?;
    if kind == 0 {
        let mut s = [0usize; 4];
        for v in &mut s {
            *v = r.u64().ok_or_else(malformed)? as usize;
        }
        let n = r.len().ok_or_else(malformed)?;
        let values = (0..n)
            .map(|_| r.f64s())
            .collect::<Option<Vec<_>>>()
            .ok_or_else(malformed)?;
        return Ok(Ok(Trajectory {
            time: grid.to_vec(),
            values,
            stats: SolverStats {
                accepted_steps: s[0],
                rejected_steps: s[1],
                rhs_evaluations: s[2],
                events: s[3],
            },
        }));
    }
    let time = r.f64().ok_or_else(malformed)?;
    let count = r.u64().ok_or_else(malformed)? as usize;
    let span = r.f64().ok_or_else(malformed)?;
    let text = r.text().ok_or_else(malformed)?;
    Ok(Err(match kind {
        1 => SimulationError::StepLimit { limit: count, time },
        2 => SimulationError::StepTooSmall { time },
        3 => SimulationError::Chattering {
            time,
            event: text,
            events: count,
            span,
        },
        4 => SimulationError::Diverged { time },
        5 => SimulationError::InvalidInput(text),
        6 => SimulationError::Failed { time, reason: text },
        _ => return Err(malformed()),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inputs::{InputSignal, Inputs, Interpolation};
    use crate::model::{SolverOptions, SolverStats};

    #[test]
    fn requests_and_replies_travel_bit_for_bit() {
        let options = SolverOptions {
            rtol: 1e-7,
            atol: 1e-9,
            max_steps: 1234,
            start_time: 0.5,
            communication_step: Some(1e-3),
        };
        let inputs = Inputs {
            signals: vec![
                InputSignal {
                    input: 1,
                    times: vec![0.0, 0.25, 0.5].into(),
                    values: vec![1.0 / 3.0, -0.0, 7.0].into(),
                    interpolation: Interpolation::Hold,
                },
                InputSignal {
                    input: 0,
                    times: vec![0.0].into(),
                    values: vec![2.5].into(),
                    interpolation: Interpolation::Linear,
                },
            ],
        };
        let (p, g, o, opts, i) = decode_request(&encode_request(
            &[0.1, f64::NAN],
            &[0.0, 0.5],
            &[2, 0],
            &options,
            &inputs,
        ))
        .unwrap();
        assert_eq!(
            (p[0], g, o, opts, i),
            (0.1, vec![0.0, 0.5], vec![2, 0], options, inputs)
        );
        assert!(p[1].is_nan());
        let t = Trajectory {
            time: vec![0.0, 1.0],
            values: vec![vec![1.0 / 3.0, -0.0]],
            stats: SolverStats {
                accepted_steps: 3,
                rejected_steps: 1,
                rhs_evaluations: 20,
                events: 2,
            },
        };
        let back = decode_reply(&encode_reply(&Ok(t.clone())), &t.time)
            .unwrap()
            .unwrap();
        assert_eq!(back, t);
        let e = SimulationError::Chattering {
            time: 1.5,
            event: "x".into(),
            events: 32,
            span: 1e-9,
        };
        let back = decode_reply(&encode_reply(&Err(e.clone())), &[]).unwrap();
        assert_eq!(back, Err(e));
    }
}
