//! Views: the encodings Foxglove decodes, written beside esgm's lossless channel.
