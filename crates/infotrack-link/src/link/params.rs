//! Reading and setting the autopilot's parameters by name.

use super::*;

/// Every parameter the vehicle listed (PARAM_REQUEST_LIST): name -> (value, type).
#[derive(Debug, Clone, Default)]
pub struct ParamList {
    /// What arrived.
    pub values: std::collections::HashMap<String, (f64, ParamType)>,
    /// Whether every index of the vehicle's count arrived: then a name not here is not on
    /// the vehicle.
    pub complete: bool,
}

impl VehicleLink {
    /// Reads every parameter in one batch (PARAM_REQUEST_LIST), asking again while parts are
    /// missing, until all have arrived or `silence` passes without a new one; says how far it
    /// is every five seconds.
    pub async fn param_list(&self, silence: Duration) -> ParamList {
        let (ts, tc) = self.target();
        let flavor = self.flavor();
        let mut rx = self.events.subscribe();
        let mut list = ParamList::default();
        let mut seen = std::collections::HashSet::new();
        let mut count: Option<u16> = None;
        let started = Instant::now();
        let mut progress_at = started + Duration::from_secs(5);
        for _ in 0..self.cfg.attempts {
            let ask = MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
                target_system: ts,
                target_component: tc,
            });
            if self.send(&ask).await.is_err() {
                return list;
            }
            while let Ok(event) = tokio::time::timeout(silence, rx.recv()).await {
                let Ok(LinkEvent::Param {
                    name,
                    wire,
                    ty: Some(t),
                    index,
                    count: n,
                }) = event
                else {
                    continue;
                };
                count = Some(n);
                seen.insert(index);
                list.values.insert(name, (decode_wire(flavor, t, wire), t));
                if Instant::now() >= progress_at {
                    progress_at += Duration::from_secs(5);
                    tracing::warn!(
                        "reading the vehicle's parameters: {} of {n} so far",
                        seen.len()
                    );
                }
                if seen.len() >= n as usize {
                    list.complete = true;
                    return list;
                }
            }
            if count.is_none() {
                // No answer at all: the vehicle does not list; asking again will not help.
                return list;
            }
        }
        list
    }

    /// Reads one parameter by name.
    pub async fn param_read(&self, name: &str) -> Result<(f64, ParamType), LinkError> {
        self.param_read_tries(name, self.cfg.attempts).await
    }

    /// Reads one parameter by name, asking at most `tries` times.
    pub async fn param_read_tries(
        &self,
        name: &str,
        tries: u32,
    ) -> Result<(f64, ParamType), LinkError> {
        let (ts, tc) = self.target();
        let mut rx = self.events.subscribe();
        for _ in 0..tries.max(1) {
            self.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: ts,
                target_component: tc,
                param_id: name.into(),
            }))
            .await?;
            if let Some((v, t)) = self.wait_param(&mut rx, name).await {
                return Ok((v, t));
            }
        }
        let hint = self.silence_hint();
        if !hint.is_empty() {
            // Not a missing parameter: the vehicle refuses to hear us.
            return Err(LinkError::Timeout {
                what: format!("the vehicle to answer for parameter {name}{hint}"),
                seconds: self.cfg.ack_timeout.as_secs_f64() * self.cfg.attempts as f64,
            });
        }
        Err(LinkError::NoSuchParam(name.to_string()))
    }

    /// Sets one parameter with the firmware's encoding and confirms the echoed value.
    pub async fn param_set(&self, name: &str, value: f64, ty: ParamType) -> Result<f64, LinkError> {
        let (ts, tc) = self.target();
        let flavor = self.flavor();
        let mut rx = self.events.subscribe();
        for _ in 0..self.cfg.attempts {
            self.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
                param_value: encode_wire(flavor, ty, value),
                target_system: ts,
                target_component: tc,
                param_id: name.into(),
                param_type: mav_param_type_of(ty),
            }))
            .await?;
            if let Some((v, _)) = self.wait_param(&mut rx, name).await {
                if (v - value).abs() <= 1e-6 * value.abs().max(1.0) {
                    return Ok(v);
                }
            }
        }
        Err(LinkError::Timeout {
            what: format!(
                "the vehicle to confirm {name} = {value}{}",
                self.silence_hint()
            ),
            seconds: self.cfg.ack_timeout.as_secs_f64() * self.cfg.attempts as f64,
        })
    }

    async fn wait_param(
        &self,
        rx: &mut broadcast::Receiver<LinkEvent>,
        name: &str,
    ) -> Option<(f64, ParamType)> {
        let flavor = self.flavor();
        let until = tokio::time::Instant::now() + self.cfg.ack_timeout;
        loop {
            match tokio::time::timeout_at(until, rx.recv()).await {
                Ok(Ok(LinkEvent::Param {
                    name: n,
                    wire,
                    ty: Some(t),
                    ..
                })) if n == name => {
                    return Some((decode_wire(flavor, t, wire), t));
                }
                Ok(Ok(_)) | Ok(Err(broadcast::error::RecvError::Lagged(_))) => continue,
                _ => return None,
            }
        }
    }
}
