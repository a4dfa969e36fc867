//! The valid frames of a padded batch, for the layers that work frame by frame.
//!
//! Why it exists: a batch pads every clip to the longest one (HDM05 kick at
//! 30 fps: 32-90 frames, 59 % of the padded frames valid), and the per-frame
//! layers (the encoder's input layer, every LSTM's input projection, the
//! decoder's output MLP, the frame discriminator) computed the padding, then
//! differentiated it, only for the losses to mask it out. [`Frames`] gathers
//! the valid rows before such a layer and scatters its output back with zeros
//! at the padding, so those layers cost what the clips hold. Measured in the
//! crate README (session 23).

use candle_core::{DType, Device, Tensor};

use crate::error::Result;

/// Which frames of a `(B, T)` batch are valid.
pub struct Frames {
    batch: usize,
    steps: usize,
    /// Row indices into the flattened `(B * T)` frames; `None` when every
    /// frame is valid (gathering would only copy).
    rows: Option<Tensor>,
    valid: usize,
}

impl Frames {
    /// From a `(B, T)` 0/1 mask (any float dtype).
    pub fn new(mask: &Tensor) -> Result<Self> {
        let (batch, steps) = mask.dims2()?;
        let m = mask.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
        let rows: Vec<u32> = m
            .iter()
            .enumerate()
            .filter(|(_, v)| **v > 0.5)
            .map(|(i, _)| i as u32)
            .collect();
        let valid = rows.len();
        let rows = if valid == batch * steps {
            None
        } else {
            Some(Tensor::from_vec(rows, valid, &Device::Cpu)?)
        };
        Ok(Frames {
            batch,
            steps,
            rows,
            valid,
        })
    }

    /// Every frame of a `(B, T)` batch valid.
    pub fn all(batch: usize, steps: usize) -> Self {
        Frames {
            batch,
            steps,
            rows: None,
            valid: batch * steps,
        }
    }

    pub fn batch(&self) -> usize {
        self.batch
    }

    pub fn steps(&self) -> usize {
        self.steps
    }

    /// How many frames are valid.
    pub fn valid(&self) -> usize {
        self.valid
    }

    /// `(B, T, F)` -> `(valid, F)`, in batch-major order.
    pub fn pack(&self, x: &Tensor) -> Result<Tensor> {
        let f = x.dim(2)?;
        let flat = x.reshape((self.batch * self.steps, f))?;
        Ok(match &self.rows {
            None => flat,
            Some(r) => flat.index_select(r, 0)?,
        })
    }

    /// `(valid, G)` -> `(B, T, G)` with zeros at the padding.
    pub fn unpack(&self, y: &Tensor) -> Result<Tensor> {
        let g = y.dim(1)?;
        let full = match &self.rows {
            None => y.clone(),
            Some(r) => Tensor::zeros((self.batch * self.steps, g), y.dtype(), y.device())?
                .index_add(r, y, 0)?,
        };
        Ok(full.reshape((self.batch, self.steps, g))?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Var;

    #[test]
    fn pack_keeps_valid_frames_and_unpack_zeroes_padding_with_gradients_through() {
        let mask = Tensor::new(&[[1f32, 1., 0.], [1., 0., 0.]], &Device::Cpu).unwrap();
        let frames = Frames::new(&mask).unwrap();
        assert_eq!(frames.valid(), 3);
        let x = Var::new(
            &[
                [[1f32, 2.], [3., 4.], [5., 6.]],
                [[7., 8.], [9., 10.], [11., 12.]],
            ],
            &Device::Cpu,
        )
        .unwrap();
        let packed = frames.pack(x.as_tensor()).unwrap();
        assert_eq!(
            packed.to_vec2::<f32>().unwrap(),
            vec![vec![1., 2.], vec![3., 4.], vec![7., 8.]]
        );
        let back = frames.unpack(&(packed * 2.0).unwrap()).unwrap();
        assert_eq!(
            back.to_vec3::<f32>().unwrap(),
            vec![
                vec![vec![2., 4.], vec![6., 8.], vec![0., 0.]],
                vec![vec![14., 16.], vec![0., 0.], vec![0., 0.]],
            ]
        );
        // d(sum)/dx is 2 on valid frames and 0 on padding.
        let grads = back.sum_all().unwrap().backward().unwrap();
        let g = grads.get(x.as_tensor()).unwrap().to_vec3::<f32>().unwrap();
        assert_eq!(g[0], vec![vec![2., 2.], vec![2., 2.], vec![0., 0.]]);
        assert_eq!(g[1], vec![vec![2., 2.], vec![0., 0.], vec![0., 0.]]);
    }

    #[test]
    fn a_full_mask_passes_through() {
        let mask = Tensor::ones((2, 3), DType::F32, &Device::Cpu).unwrap();
        let frames = Frames::new(&mask).unwrap();
        assert_eq!(frames.valid(), 6);
        let x = Tensor::arange(0f32, 12., &Device::Cpu)
            .unwrap()
            .reshape((2, 3, 2))
            .unwrap();
        let round = frames.unpack(&frames.pack(&x).unwrap()).unwrap();
        assert_eq!(round.to_vec3::<f32>().unwrap(), x.to_vec3::<f32>().unwrap());
    }
}
