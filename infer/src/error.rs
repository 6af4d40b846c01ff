//! The crate's one error type: reading a model, checking it against a contract, running it.

/// What can go wrong reading, checking or running a model.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum Error {
    /// The file cannot be read.
    #[error("cannot read {path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        message: String,
    },
    /// The bytes are not a valid ONNX protobuf.
    #[error("not a valid ONNX model: {0}")]
    Malformed(String),
    /// A construct the reader does not take (external data, an unsupported tensor type...).
    #[error("unsupported ONNX content: {0}")]
    Unsupported(String),
    /// An op the executor does not have.
    #[error("unsupported ONNX op `{op}` at node {node}")]
    UnsupportedOp {
        /// Op type.
        op: String,
        /// Node label.
        node: String,
    },
    /// Shapes or values a node cannot take.
    #[error("node {node}: {message}")]
    Invalid {
        /// Node label.
        node: String,
        /// What is wrong.
        message: String,
    },
    /// Shape arithmetic that cannot be done (an axis out of range, a reshape that does not
    /// fit), before it is placed at a node.
    #[error("{0}")]
    Shape(String),
    /// The model does not fit what its user reads from it (a detector's square input, a
    /// decoder's output layout, a segmenter's class count).
    #[error("{0}")]
    Contract(String),
    /// A backend refused the model or a run (its message).
    #[error("{0}")]
    Backend(String),
    /// An input the model needs was not given.
    #[error("input `{0}` not given")]
    MissingInput(String),
}

/// The reference executor's op bodies report plain messages, placed at their node by the
/// caller; a shape error becomes one of those messages.
impl From<Error> for String {
    fn from(e: Error) -> String {
        e.to_string()
    }
}
