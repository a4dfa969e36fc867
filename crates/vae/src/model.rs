//! The MotionAug VAE (Sec. 3.1, Fig. 3): encoder, decoder and the two
//! discriminators, as one struct owning every parameter.
//!
//! * Encoder: LayerNorm -> Linear + ReLU -> BiLSTM -> mean over valid frames ->
//!   two MLP heads for mu and log sigma^2.
//! * Decoder: Linear(latent) repeated over time -> LSTM -> MLP to a frame.
//! * Frame discriminator: MLP scoring each frame.
//! * Sequence discriminator: BiLSTM -> mean over valid frames -> Linear to a score.
//!
//! All tensors are normalised features (see `normalize`), `(B, T, F)`, with a
//! `(B, T)` mask of valid frames (sequences padded at the end).

use candle_core::{D, Tensor};
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};
use crate::frames::Frames;
use crate::lstm::{BiLstm, Lstm, masked_mean};
use nn::{LayerNorm, Linear, Mlp, MlpConfig, Params};

/// Layer sizes. [`VaeConfig::reference`] is the paper's; the default is small enough
/// to train a class in minutes on two CPU cores.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct VaeConfig {
    /// Encoder input projection (Linear + ReLU before the BiLSTM).
    pub enc_input: usize,
    /// Encoder BiLSTM hidden size per direction.
    pub enc_hidden: usize,
    /// Hidden layers of the mu / logvar heads (input is 2 * enc_hidden).
    pub head_hidden: Vec<usize>,
    pub latent: usize,
    /// Width of the decoder's per-frame input (Linear of z, repeated over time).
    pub dec_input: usize,
    pub dec_hidden: usize,
    /// Hidden layers of the decoder's output MLP.
    pub dec_mlp_hidden: Vec<usize>,
    pub frame_disc_hidden: Vec<usize>,
    /// Sequence discriminator BiLSTM hidden size per direction.
    pub seq_disc_hidden: usize,
}

impl VaeConfig {
    /// Sizes from the MotionAug reference implementation.
    pub fn reference() -> Self {
        VaeConfig {
            enc_input: 128,
            enc_hidden: 256,
            head_hidden: vec![256],
            latent: 128,
            dec_input: 128,
            dec_hidden: 256,
            dec_mlp_hidden: vec![256],
            frame_disc_hidden: vec![256, 256],
            seq_disc_hidden: 256,
        }
    }

    /// Tiny sizes for tests.
    pub fn tiny() -> Self {
        VaeConfig {
            enc_input: 16,
            enc_hidden: 16,
            head_hidden: vec![16],
            latent: 8,
            dec_input: 16,
            dec_hidden: 32,
            dec_mlp_hidden: vec![],
            frame_disc_hidden: vec![16],
            seq_disc_hidden: 8,
        }
    }

    pub fn validate(&self) -> Result<()> {
        let sizes = [
            ("enc_input", self.enc_input),
            ("enc_hidden", self.enc_hidden),
            ("latent", self.latent),
            ("dec_input", self.dec_input),
            ("dec_hidden", self.dec_hidden),
            ("seq_disc_hidden", self.seq_disc_hidden),
        ];
        for (name, v) in sizes {
            if v == 0 || v > 8192 {
                return Err(VaeError::Config(format!(
                    "{name} = {v}: must be in 1..=8192"
                )));
            }
        }
        let lists = [
            ("head_hidden", &self.head_hidden),
            ("dec_mlp_hidden", &self.dec_mlp_hidden),
            ("frame_disc_hidden", &self.frame_disc_hidden),
        ];
        for (name, l) in lists {
            if l.iter().any(|&v| v == 0 || v > 8192) {
                return Err(VaeError::Config(format!(
                    "{name} = {l:?}: sizes must be in 1..=8192"
                )));
            }
        }
        Ok(())
    }
}

impl Default for VaeConfig {
    fn default() -> Self {
        VaeConfig {
            enc_input: 64,
            enc_hidden: 128,
            head_hidden: vec![128],
            latent: 64,
            dec_input: 64,
            dec_hidden: 128,
            dec_mlp_hidden: vec![128],
            frame_disc_hidden: vec![128, 128],
            seq_disc_hidden: 64,
        }
    }
}

pub struct Encoder {
    norm: LayerNorm,
    input: Linear,
    lstm: BiLstm,
    mu: Mlp,
    logvar: Mlp,
}

impl Encoder {
    /// `(mu, logvar)`, each `(B, latent)`. The per-frame layers see the valid
    /// frames only ([`Frames`]).
    pub fn forward(&self, x: &Tensor, mask: &Tensor) -> Result<(Tensor, Tensor)> {
        let frames = Frames::new(mask)?;
        let rows = self.norm.forward(&frames.pack(x)?)?;
        let rows = self.input.forward(&rows)?.relu()?;
        let h = self.lstm.forward_rows(&rows, &frames, mask)?;
        let pooled = masked_mean(&h, mask)?;
        Ok((self.mu.forward(&pooled)?, self.logvar.forward(&pooled)?))
    }
}

pub struct Decoder {
    input: Linear,
    lstm: Lstm,
    out: Mlp,
}

impl Decoder {
    /// `z` `(B, latent)` -> `(B, frames, F)`. A forward-only LSTM: frame t does not
    /// depend on the total length, so one batch can decode several lengths.
    pub fn forward(&self, z: &Tensor, frames: usize) -> Result<Tensor> {
        let (b, _) = z.dims2()?;
        self.decode(z, &Frames::all(b, frames))
    }

    /// The same for training: only the frames `mask` `(B, T)` marks valid are
    /// put through the output MLP; the padding decodes to zeros.
    pub fn forward_masked(&self, z: &Tensor, mask: &Tensor) -> Result<Tensor> {
        self.decode(z, &Frames::new(mask)?)
    }

    fn decode(&self, z: &Tensor, frames: &Frames) -> Result<Tensor> {
        // The code, repeated over time, is the LSTM's input at every step.
        let h = self
            .lstm
            .forward_repeated(&self.input.forward(z)?, frames.steps())?;
        frames.unpack(&self.out.forward(&frames.pack(&h)?)?)
    }
}

pub struct FrameDiscriminator {
    mlp: Mlp,
}

impl FrameDiscriminator {
    /// One score per frame, `(B, T)`; with a mask, valid frames only are
    /// scored (the padding gets 0).
    pub fn forward(&self, x: &Tensor, mask: Option<&Tensor>) -> Result<Tensor> {
        let scores = match mask {
            None => self.mlp.forward(x)?,
            Some(m) => {
                let frames = Frames::new(m)?;
                frames.unpack(&self.mlp.forward(&frames.pack(x)?)?)?
            }
        };
        Ok(scores.squeeze(D::Minus1)?)
    }
}

pub struct SequenceDiscriminator {
    lstm: BiLstm,
    out: Linear,
}

impl SequenceDiscriminator {
    /// One score per sequence, `(B,)`.
    pub fn forward(&self, x: &Tensor, mask: &Tensor) -> Result<Tensor> {
        let h = masked_mean(&self.lstm.forward(x, mask)?, mask)?;
        Ok(self.out.forward(&h)?.squeeze(D::Minus1)?)
    }
}

/// Parameter-name prefixes of the generator (encoder + decoder) and discriminators.
pub const GENERATOR: [&str; 2] = ["enc.", "dec."];
pub const DISCRIMINATORS: [&str; 2] = ["fdis.", "sdis."];

pub struct Vae {
    pub config: VaeConfig,
    pub frame_dim: usize,
    pub encoder: Encoder,
    pub decoder: Decoder,
    pub frame_disc: FrameDiscriminator,
    pub seq_disc: SequenceDiscriminator,
    pub params: Params,
}

impl Vae {
    pub fn new(config: &VaeConfig, frame_dim: usize, seed: u64) -> Result<Self> {
        config.validate()?;
        if frame_dim == 0 {
            return Err(VaeError::Config("frame dimension is 0".into()));
        }
        let c = config;
        let p = Params::new(seed);
        let encoder = Encoder {
            norm: LayerNorm::new(&p, "enc.norm", frame_dim)?,
            input: Linear::new(&p, "enc.input", frame_dim, c.enc_input)?,
            lstm: BiLstm::new(&p, "enc.lstm", c.enc_input, c.enc_hidden)?,
            mu: Mlp::new(
                &MlpConfig::new(2 * c.enc_hidden, &c.head_hidden, c.latent),
                &p,
                "enc.mu",
            )?,
            logvar: Mlp::new(
                &MlpConfig::new(2 * c.enc_hidden, &c.head_hidden, c.latent),
                &p,
                "enc.logvar",
            )?,
        };
        let decoder = Decoder {
            input: Linear::new(&p, "dec.input", c.latent, c.dec_input)?,
            lstm: Lstm::new(&p, "dec.lstm", c.dec_input, c.dec_hidden)?,
            out: Mlp::new(
                &MlpConfig::new(c.dec_hidden, &c.dec_mlp_hidden, frame_dim),
                &p,
                "dec.out",
            )?,
        };
        let frame_disc = FrameDiscriminator {
            mlp: Mlp::new(
                &MlpConfig::new(frame_dim, &c.frame_disc_hidden, 1),
                &p,
                "fdis.mlp",
            )?,
        };
        let seq_disc = SequenceDiscriminator {
            lstm: BiLstm::new(&p, "sdis.lstm", frame_dim, c.seq_disc_hidden)?,
            out: Linear::new(&p, "sdis.out", 2 * c.seq_disc_hidden, 1)?,
        };
        Ok(Vae {
            config: config.clone(),
            frame_dim,
            encoder,
            decoder,
            frame_disc,
            seq_disc,
            params: p,
        })
    }
}
