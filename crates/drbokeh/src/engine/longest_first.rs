//! Work items run on the thread pool largest predicted cost first, each worker taking the
//! next item when it finishes one (longest processing time first). Rayon's own split
//! halves the item list by index, so when the cost grows across the image (a blur that
//! grows towards the bottom) one worker gets the expensive half and the other idles at
//! the end; taken largest first, the last item to finish is a cheap one.

use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Runs `f` on every item (with its index), largest `cost` first, and returns the results
/// in item order. Equal costs keep item order. The results do not depend on the number of
/// threads or on which thread ran what.
pub(crate) fn map_longest_first<I: Send, R: Send>(
    items: Vec<I>,
    cost: &[f64],
    f: impl Fn(usize, I) -> R + Sync,
) -> Vec<R> {
    assert_eq!(items.len(), cost.len(), "one cost per item");
    let n = items.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| cost[b].total_cmp(&cost[a]).then(a.cmp(&b)));
    let slots: Vec<Mutex<Option<I>>> = items.into_iter().map(|i| Mutex::new(Some(i))).collect();
    let next = AtomicUsize::new(0);
    let workers = rayon::current_num_threads().min(n).max(1);
    let mut done: Vec<(usize, R)> = (0..workers)
        .into_par_iter()
        .flat_map_iter(|_| {
            let mut mine = Vec::new();
            loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(&index) = order.get(k) else { break };
                let item = slots[index]
                    .lock()
                    .expect("no worker panics holding a slot")
                    .take()
                    .expect("each item is taken once");
                mine.push((index, f(index, item)));
            }
            mine
        })
        .collect();
    done.sort_by_key(|&(index, _)| index);
    done.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_once_in_item_order_for_any_pool() {
        let costs = [1.0, 5.0, 3.0, 5.0, 0.0, 2.0, 9.0];
        for threads in [1, 2, 3, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let out = pool.install(|| {
                map_longest_first((0..costs.len()).collect(), &costs, |i, item: usize| {
                    assert_eq!(i, item);
                    item * 10
                })
            });
            assert_eq!(out, vec![0, 10, 20, 30, 40, 50, 60], "{threads} threads");
        }
        let empty: Vec<u8> = map_longest_first(Vec::<u8>::new(), &[], |_, v| v);
        assert!(empty.is_empty());
    }

    #[test]
    fn one_worker_takes_the_largest_cost_first() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let seen = Mutex::new(Vec::new());
        pool.install(|| {
            map_longest_first(vec!['a', 'b', 'c', 'd'], &[1.0, 3.0, 2.0, 3.0], |i, _| {
                seen.lock().unwrap().push(i)
            })
        });
        assert_eq!(*seen.lock().unwrap(), vec![1, 3, 2, 0]);
    }
}
