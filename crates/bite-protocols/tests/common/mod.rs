//! What the protocol tests that drive one kernel by hand share.

use bite_core::RobotId;
use bite_core::msg::{Body, Envelope, InstanceKey};

/// Robot `r`'s message number `seq` for instance `key`.
pub fn from(r: u32, key: InstanceKey, seq: u64, body: Body) -> Envelope {
    Envelope {
        instance: key,
        sender: RobotId(r),
        seq,
        body,
    }
}
