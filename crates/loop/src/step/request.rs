//! The operator's requests to the loop: what a cycle's input may carry
//! ([`super::LoopInput::request`]), each answered in that cycle. Each is
//! declared once, in the command table (`sar_msgs::command`: its wire and
//! recorded codes, its arguments with their units, its log text and help);
//! the loop's handling of each is in [`super`]'s `answer_request`.

pub use sar_msgs::command::Request;
