//! Who is signed in to the web app, and who may still try: sessions kept on the server and
//! the throttle on wrong tokens.
//!
//! - **Sessions.** Each login draws a session key of its own (256 random bits); the server
//!   keeps only its BLAKE3 hash and its expiry. A cookie is valid while its session is kept:
//!   [`SESSION_LIFETIME`] after the login, until `/logout` revokes it, or until the server
//!   stops. At most [`MAX_SESSIONS`] are kept; a login beyond them ends the session closest to
//!   its expiry.
//! - **Throttle.** Wrong tokens are counted per client address (a login, or a bearer token on
//!   an API route). The first [`FREE_FAILURES`] − 1 cost nothing (typing mistakes); from the
//!   [`FREE_FAILURES`]-th on, each wrong token closes the address for a delay that doubles
//!   from one second up to [`MAX_DELAY`], during which every token it presents, right or
//!   wrong, is refused unread (429, `Retry-After`). A right token opens it again. So an
//!   address tries at most a handful of tokens in its first seconds and then about one every
//!   five minutes. At most [`MAX_ADDRESSES`] addresses are remembered (the least recently
//!   failing are forgotten first).

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::{Duration, Instant};

/// How long a session lasts after its login.
pub const SESSION_LIFETIME: Duration = Duration::from_secs(12 * 3600);

/// Most sessions kept at once.
pub const MAX_SESSIONS: usize = 1024;

/// The wrong token at which an address is first closed (for [`BASE_DELAY`]).
pub const FREE_FAILURES: u32 = 5;

/// The first closing's length; each further wrong token doubles it.
pub const BASE_DELAY: Duration = Duration::from_secs(1);

/// The longest an address is closed after one wrong token.
pub const MAX_DELAY: Duration = Duration::from_secs(300);

/// Most client addresses whose wrong tokens are remembered.
pub const MAX_ADDRESSES: usize = 4096;

/// The sessions the server has issued and not yet ended.
#[derive(Debug, Default)]
pub struct Sessions {
    /// BLAKE3 of each session key → when it expires.
    live: HashMap<[u8; 32], Instant>,
}

impl Sessions {
    /// A new session valid from `now`: its key (hex, 64 characters), for the cookie.
    pub fn open(&mut self, now: Instant) -> String {
        self.live.retain(|_, expiry| *expiry > now);
        if self.live.len() >= MAX_SESSIONS {
            let oldest = self
                .live
                .iter()
                .min_by_key(|(_, expiry)| **expiry)
                .map(|(k, _)| *k);
            if let Some(k) = oldest {
                self.live.remove(&k);
            }
        }
        let key: [u8; 32] = rand::random();
        let key = calib_engine::store::hex(&key);
        self.live.insert(
            *blake3::hash(key.as_bytes()).as_bytes(),
            now + SESSION_LIFETIME,
        );
        key
    }

    /// Whether `key` is a session valid at `now`.
    pub fn valid(&self, key: &str, now: Instant) -> bool {
        self.live
            .get(blake3::hash(key.as_bytes()).as_bytes())
            .is_some_and(|expiry| *expiry > now)
    }

    /// End the session `key` (nothing when it is not one).
    pub fn revoke(&mut self, key: &str) {
        self.live.remove(blake3::hash(key.as_bytes()).as_bytes());
    }

    /// Sessions kept.
    pub fn len(&self) -> usize {
        self.live.len()
    }

    pub fn is_empty(&self) -> bool {
        self.live.is_empty()
    }
}

/// One address's record of wrong tokens.
#[derive(Debug, Clone, Copy)]
struct Failures {
    count: u32,
    /// Closed until then.
    closed_until: Instant,
}

/// Wrong tokens per client address.
#[derive(Debug, Default)]
pub struct Throttle {
    addresses: HashMap<IpAddr, Failures>,
}

impl Throttle {
    /// How long `address` stays closed after `now` (`None`: it may present a token).
    pub fn closed(&self, address: IpAddr, now: Instant) -> Option<Duration> {
        let f = self.addresses.get(&address)?;
        (f.closed_until > now).then(|| f.closed_until - now)
    }

    /// A wrong token from `address` at `now`: how long it is closed from now on.
    pub fn failed(&mut self, address: IpAddr, now: Instant) -> Option<Duration> {
        if !self.addresses.contains_key(&address) && self.addresses.len() >= MAX_ADDRESSES {
            self.forget_one(now);
        }
        let f = self.addresses.entry(address).or_insert(Failures {
            count: 0,
            closed_until: now,
        });
        f.count = f.count.saturating_add(1);
        let delay = delay_after(f.count)?;
        f.closed_until = now + delay;
        Some(delay)
    }

    /// A right token from `address`: it starts afresh.
    pub fn succeeded(&mut self, address: IpAddr) {
        self.addresses.remove(&address);
    }

    /// Drop the address whose closing ended first (an open one before any closed one).
    fn forget_one(&mut self, now: Instant) {
        let first = self
            .addresses
            .iter()
            .min_by_key(|(_, f)| (f.closed_until > now, f.closed_until))
            .map(|(a, _)| *a);
        if let Some(a) = first {
            self.addresses.remove(&a);
        }
    }
}

/// The closing after the `count`-th consecutive wrong token: none before [`FREE_FAILURES`],
/// then [`BASE_DELAY`] doubling up to [`MAX_DELAY`].
pub fn delay_after(count: u32) -> Option<Duration> {
    let past = count.checked_sub(FREE_FAILURES)?;
    let factor = 1u32.checked_shl(past.min(31)).unwrap_or(u32::MAX);
    Some(BASE_DELAY.saturating_mul(factor).min(MAX_DELAY))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_delay_doubles_from_the_fifth_wrong_token_to_five_minutes() {
        let delays: Vec<Option<u64>> = (1..=16)
            .map(|n| delay_after(n).map(|d| d.as_secs()))
            .collect();
        assert_eq!(
            delays,
            [
                None,
                None,
                None,
                None,
                Some(1),
                Some(2),
                Some(4),
                Some(8),
                Some(16),
                Some(32),
                Some(64),
                Some(128),
                Some(256),
                Some(300),
                Some(300),
                Some(300)
            ]
        );
        assert_eq!(delay_after(u32::MAX), Some(MAX_DELAY));
    }

    #[test]
    fn an_address_is_closed_after_its_wrong_tokens_and_opened_by_a_right_one() {
        let mut t = Throttle::default();
        let (a, b): (IpAddr, IpAddr) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        let t0 = Instant::now();
        for _ in 1..FREE_FAILURES {
            assert_eq!(t.failed(a, t0), None);
            assert_eq!(t.closed(a, t0), None);
        }
        assert_eq!(t.failed(a, t0), Some(Duration::from_secs(1)));
        assert_eq!(t.closed(a, t0), Some(Duration::from_secs(1)));
        assert_eq!(t.closed(b, t0), None, "per address");
        let later = t0 + Duration::from_millis(1500);
        assert_eq!(t.closed(a, later), None);
        assert_eq!(t.failed(a, later), Some(Duration::from_secs(2)));
        t.succeeded(a);
        assert_eq!(t.closed(a, later), None);
        assert_eq!(t.failed(a, later), None, "counted afresh");
    }

    #[test]
    fn the_addresses_remembered_are_bounded_and_closed_ones_are_kept_longest() {
        let mut t = Throttle::default();
        let now = Instant::now();
        let closed: IpAddr = "192.0.2.1".parse().unwrap();
        for _ in 0..FREE_FAILURES {
            t.failed(closed, now);
        }
        for i in 0..(MAX_ADDRESSES as u32 + 100) {
            t.failed(IpAddr::from(i.to_be_bytes()), now);
        }
        assert_eq!(t.addresses.len(), MAX_ADDRESSES);
        assert!(t.closed(closed, now).is_some());
    }

    #[test]
    fn each_login_is_a_session_of_its_own_until_revoked_or_expired() {
        let mut s = Sessions::default();
        let t0 = Instant::now();
        let (one, two) = (s.open(t0), s.open(t0));
        assert_ne!(one, two);
        assert_eq!(one.len(), 64);
        assert!(s.valid(&one, t0) && s.valid(&two, t0));
        assert!(!s.valid(&"0".repeat(64), t0));
        s.revoke(&one);
        assert!(!s.valid(&one, t0) && s.valid(&two, t0));
        let expired = t0 + SESSION_LIFETIME;
        assert!(!s.valid(&two, expired));
        let three = s.open(expired);
        assert_eq!(s.len(), 1, "expired sessions are dropped");
        assert!(s.valid(&three, expired));
    }

    #[test]
    fn the_sessions_kept_are_bounded_the_oldest_ending_first() {
        let mut s = Sessions::default();
        let t0 = Instant::now();
        let first = s.open(t0);
        let keys: Vec<String> = (1..=MAX_SESSIONS)
            .map(|i| s.open(t0 + Duration::from_millis(i as u64)))
            .collect();
        assert_eq!(s.len(), MAX_SESSIONS);
        assert!(!s.valid(&first, t0));
        assert!(keys.iter().all(|k| s.valid(k, t0)));
    }
}
