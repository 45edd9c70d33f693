import json,sys,glob,collections
T=collections.Counter();C=collections.Counter();F=collections.Counter();FC=collections.Counter();cpu=0
for f in glob.glob(sys.argv[1]+'.*.json'):
    d=json.load(open(f)); cpu+=d['cpu']; T.update(d['tot']); C.update(d['cnt']); F.update(d['fn']); FC.update(d['fnc'])
print('cpu',round(cpu))
for k,v in T.most_common(): print(f'{v:8.1f} {C[k]:6d} {k}')
for k,v in F.most_common(int(sys.argv[2]) if len(sys.argv)>2 else 40): print(f'{v:8.2f} {FC[k]:5d} {k}')
