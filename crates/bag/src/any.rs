//! Any message type the project knows, chosen by the recorded type name.

use softcontact_msgs::RosType;

use crate::{BagMessage, BagWriter, Result};

macro_rules! any_message {
    ($($variant:ident: $ty:ty),+ $(,)?) => {
        /// One message of any type the nodes publish or take.
        #[derive(Debug, Clone, PartialEq, serde::Serialize)]
        #[serde(untagged)]
        pub enum AnyMessage {
            $($variant($ty)),+
        }

        impl AnyMessage {
            /// Decodes a recorded message; `None` when its type is not one the project knows.
            pub fn decode(msg: &BagMessage<'_>) -> Result<Option<Self>> {
                $(if msg.is::<$ty>() {
                    return Ok(Some(Self::$variant(msg.decode::<$ty>()?)));
                })+
                Ok(None)
            }

            /// `pkg/msg/Type`.
            pub fn type_path(&self) -> String {
                match self {
                    $(Self::$variant(_) => <$ty>::type_path()),+
                }
            }

            /// Whether the project knows the type named `pkg/msg/Type` (or `pkg/Type`).
            pub fn is_known(type_name: &str) -> bool {
                let path = crate::type_path(type_name);
                false $(|| path == <$ty>::type_path())+
            }

            /// Writes the message on a channel added for its type.
            pub fn write_to_channel(&self, writer: &mut BagWriter, channel: u16, log_time: u64) -> Result<()> {
                match self {
                    $(Self::$variant(m) => writer.write(channel, log_time, m)),+
                }
            }

            /// Adds `topic` with this message's type (if new) and writes the message.
            pub fn write(&self, writer: &mut BagWriter, topic: &str, qos: crate::Qos, log_time: u64) -> Result<()> {
                match self {
                    $(Self::$variant(m) => {
                        let channel = writer.add_topic::<$ty>(topic, qos)?;
                        writer.write(channel, log_time, m)
                    }),+
                }
            }
        }
    };
}

softcontact_msgs::with_message_types!(any_message);
