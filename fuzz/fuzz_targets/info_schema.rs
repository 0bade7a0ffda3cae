//! The info-column schema a Python worker announces (`InfoSchema::parse`, JSON text in an
//! info): a schema that passes lays every value and flag inside the row, aligned, after the
//! id, for rows of several sizes.
#![no_main]

use envhub_protocol::info_columns::InfoSchema;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    for row in [0usize, 8, 16, 48, 512] {
        let Ok(schema) = InfoSchema::parse(&text, row) else {
            continue;
        };
        assert_ne!(schema.id, 0);
        let mut taken = vec![(0usize, 8usize)];
        for c in &schema.columns {
            let item: usize = c.dtype[2..].parse().expect("a dtype's item size");
            let whole = c.shape.iter().try_fold(item, |a, &d| a.checked_mul(d));
            assert_eq!(whole, Some(c.nbytes), "{c:?}");
            assert!(
                c.offset + c.nbytes <= row && c.mask < row,
                "{c:?} in a row of {row}"
            );
            assert!(c.offset % item == 0, "{c:?} unaligned");
            if c.nbytes > 0 {
                taken.push((c.offset, c.offset + c.nbytes));
            }
            taken.push((c.mask, c.mask + 1));
        }
        taken.sort_unstable();
        assert!(
            taken.windows(2).all(|w| w[0].1 <= w[1].0),
            "overlapping columns in {schema:?}"
        );
    }
});
